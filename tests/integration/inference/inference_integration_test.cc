// The real `inference` binary on an ephemeral loopback port: trains from a
// server-side paired corpus (built from tests/data: real speech + real motion,
// synthetic pairing), evaluates, streams, stops gracefully, and serves the
// stored model again after a restart.
#include <fstream>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "common/testing/process.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "services/inference/corpus/corpus.h"

namespace kinemo::inference {
namespace {

namespace v1 = ::kinemo::inference::v1;
using kinemo::testing::ServiceProcess;

const std::string kData = KINEMO_TEST_DATA_DIR;

std::unique_ptr<grpc::ClientContext> Ctx(int seconds = 60) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  return c;
}

TEST(InferenceBinary, TrainsFromServerCorpusAndServesAfterRestart) {
  const std::string binary = kinemo::testing::FindBuiltBinary(KINEMO_BINARY_DIR, "inference");
  ASSERT_FALSE(binary.empty());
  kinemo::testing::TempDir dir;
  SyntheticCorpusOptions co;
  co.speech_files = {kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav",
                     kData + "/speech/sense_and_sensibility_01_austen_64kb-0930.wav"};
  co.gesture_files = {kData + "/motion/dataset-1_bye_normal_001.bvh"};
  co.out_dir = dir.File("corpora/tiny");
  co.renditions = 3;
  ASSERT_TRUE(BuildSyntheticCorpus(co).ok());
  const std::string config = dir.File("inference.textproto");
  std::ofstream(config) << "model_dir: \"" << dir.File("models") << "\"\n"
                        << "corpus_root: \"" << dir.File("corpora") << "\"\n"
                        << "defaults { num_states: 3 window: 2 num_clusters: 3 hmm_restarts: 2 }\n";

  auto svc = ServiceProcess::Start({.binary = binary,
                                    .args = {"--config", config},
                                    .health_service = v1::InferenceService::service_full_name()});
  ASSERT_TRUE(svc.ok()) << svc.status();
  auto stub = v1::InferenceService::NewStub((*svc)->Channel());

  v1::TrainRequest treq;
  treq.set_model_id("tiny");
  treq.set_corpus_dir("tiny");
  treq.set_description("tests/data synthetic pairing");
  auto tctx = Ctx(120);
  auto reader = stub->Train(tctx.get(), treq);
  v1::TrainResponse tr, last;
  int messages = 0;
  while (reader->Read(&tr)) {
    last = tr;
    ++messages;
  }
  ASSERT_TRUE(reader->Finish().ok());
  ASSERT_TRUE(last.has_model());
  EXPECT_EQ(last.model().num_states(), 3u);
  EXPECT_EQ(last.model().training_sequences(), 6u);
  EXPECT_GE(messages, 3);

  v1::EvaluateRequest ereq;
  ereq.set_model_id("tiny");
  ereq.set_corpus_dir("tiny");
  v1::EvaluateResponse eresp;
  ASSERT_TRUE(stub->Evaluate(Ctx().get(), ereq, &eresp).ok());
  EXPECT_EQ(eresp.sequences_size(), 6);
  EXPECT_TRUE(std::isfinite(eresp.crf_ll_per_step()));

  ereq.set_corpus_dir("../../etc");
  EXPECT_EQ(stub->Evaluate(Ctx().get(), ereq, &eresp).error_code(), grpc::StatusCode::FAILED_PRECONDITION);

  auto code = (*svc)->Stop();
  ASSERT_TRUE(code.ok());
  EXPECT_EQ(*code, 0);

  // Restart with the model preloaded: it is read back from the store.
  std::ofstream(config, std::ios::app) << "preload_model_ids: \"tiny\"\n";
  auto again = ServiceProcess::Start({.binary = binary,
                                      .args = {"--config", config},
                                      .health_service = v1::InferenceService::service_full_name()});
  ASSERT_TRUE(again.ok()) << again.status();
  auto stub2 = v1::InferenceService::NewStub((*again)->Channel());
  v1::GetModelRequest greq;
  greq.set_model_id("tiny");
  greq.set_include_parameters(true);
  v1::GetModelResponse gresp;
  ASSERT_TRUE(stub2->GetModel(Ctx().get(), greq, &gresp).ok());
  EXPECT_EQ(gresp.info().description(), "tests/data synthetic pairing");
  EXPECT_EQ(gresp.parameters().states_size(), 3);

  auto sctx = Ctx();
  auto stream = stub2->StreamInfer(sctx.get());
  v1::StreamInferRequest sreq;
  sreq.mutable_config()->set_model_id("tiny");
  ASSERT_TRUE(stream->Write(sreq));
  for (int t = 0; t < 10; ++t) {
    auto* f = sreq.mutable_features();
    f->set_start_s(0.2 * t);
    f->set_end_s(0.2 * t + 0.2);
    f->set_length_s(0.2);
    f->set_voiced(t % 3 != 0);
    f->set_f0_mean_hz(120 + 5 * t);
    f->set_intensity_mean_db(60 + t % 4);
    ASSERT_TRUE(stream->Write(sreq));
  }
  stream->WritesDone();
  v1::StreamInferResponse sresp;
  int beliefs = 0;
  while (stream->Read(&sresp)) beliefs += sresp.has_filtered() ? 1 : 0;
  EXPECT_TRUE(stream->Finish().ok());
  EXPECT_EQ(beliefs, 10);
  EXPECT_EQ(*(*again)->Stop(), 0);
}

}  // namespace
}  // namespace kinemo::inference
