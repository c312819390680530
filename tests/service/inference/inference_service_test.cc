// In-process tests of the inference gRPC service: train on planted data,
// infer, stream, evaluate, list, and the error mapping.
#include "services/inference/inference_service.h"

#include <filesystem>
#include <random>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "common/server/service_host.h"
#include "tests/unit/inference/planted.h"

namespace kinemo::inference {
namespace {

namespace fs = std::filesystem;

class InferenceServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) / ("kinemo_inf_svc_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    v1::InferenceOptions o;
    o.set_model_dir(dir_.string());
    auto svc = InferenceServiceImpl::Create(o);
    ASSERT_TRUE(svc.ok()) << svc.status();
    common::v1::ServerOptions so;
    so.set_host("127.0.0.1");
    so.set_port(0);
    so.set_shutdown_grace_s(1);
    auto host = server::ServiceHost::Start(so, "inference-test",
                                           {{*svc, v1::InferenceService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = *std::move(host);
    stub_ = v1::InferenceService::NewStub(host_->InProcessChannel());
    testing::PlantedPipeline planted(4, 0, 21);
    std::mt19937_64 rng(5);
    for (int k = 0; k < 4; ++k) train_.push_back(planted.Sample(300, rng, nullptr));
    test_ = planted.Sample(120, rng, nullptr);
  }
  void TearDown() override {
    host_->Shutdown();
    fs::remove_all(dir_);
  }

  grpc::Status TrainModel(const std::string& id, bool overwrite, std::vector<v1::TrainResponse>* out) {
    v1::TrainRequest req;
    req.set_model_id(id);
    req.set_overwrite(overwrite);
    req.set_description("planted");
    for (const auto& s : train_) *req.mutable_sequences()->add_sequences() = ToProto(s);
    req.mutable_params()->set_num_states(4);
    req.mutable_params()->set_window(3);
    req.mutable_params()->set_num_clusters(6);
    req.mutable_params()->set_hmm_restarts(2);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    auto reader = stub_->Train(&ctx, req);
    v1::TrainResponse r;
    while (reader->Read(&r)) out->push_back(r);
    return reader->Finish();
  }

  std::unique_ptr<grpc::ClientContext> Ctx() {
    auto c = std::make_unique<grpc::ClientContext>();
    c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    return c;
  }

  fs::path dir_;
  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::InferenceService::Stub> stub_;
  std::vector<PairedSequence> train_;
  PairedSequence test_;
};

TEST_F(InferenceServiceTest, TrainInferStreamEvaluateList) {
  std::vector<v1::TrainResponse> progress;
  ASSERT_TRUE(TrainModel("planted", false, &progress).ok());
  ASSERT_GE(progress.size(), 3u);
  ASSERT_TRUE(progress.back().has_model());
  EXPECT_EQ(progress.back().model().model_id(), "planted");
  EXPECT_EQ(progress.back().model().version(), 1u);
  EXPECT_EQ(progress.back().model().training_steps(), 1200u);
  EXPECT_EQ(progress.back().model().lookahead_steps(), 1u);
  bool saw_crf = false;
  for (const auto& p : progress) saw_crf = saw_crf || p.progress().stage() == "crf_optimize";
  EXPECT_TRUE(saw_crf);

  // Infer.
  v1::InferRequest ireq;
  ireq.set_model_id("planted");
  ireq.set_include_filtered(true);
  ireq.set_include_viterbi(true);
  ireq.set_include_expected_kinematics(true);
  *ireq.mutable_inputs() = ToProto(test_).inputs();
  v1::InferResponse iresp;
  ASSERT_TRUE(stub_->Infer(Ctx().get(), ireq, &iresp).ok());
  ASSERT_EQ(iresp.smoothed_size(), 120);
  ASSERT_EQ(iresp.filtered_size(), 120);
  EXPECT_EQ(iresp.viterbi_states_size(), 120);
  EXPECT_EQ(iresp.expected_kinematics_size(), 120);
  double sum = 0;
  for (double p : iresp.smoothed(7).probabilities()) sum += p;
  EXPECT_NEAR(sum, 1.0, 1e-9);

  // StreamInfer matches Infer's filtered beliefs.
  auto ctx = Ctx();
  auto stream = stub_->StreamInfer(ctx.get());
  v1::StreamInferRequest sreq;
  sreq.mutable_config()->set_model_id("planted");
  ASSERT_TRUE(stream->Write(sreq));
  for (const auto& f : ireq.inputs()) {
    *sreq.mutable_features() = f;
    ASSERT_TRUE(stream->Write(sreq));
  }
  stream->WritesDone();
  v1::StreamInferResponse sresp;
  ASSERT_TRUE(stream->Read(&sresp));
  ASSERT_TRUE(sresp.has_model());
  int n = 0;
  while (stream->Read(&sresp)) {
    ASSERT_TRUE(sresp.has_filtered());
    EXPECT_EQ(sresp.filtered().step(), static_cast<std::uint64_t>(n));
    for (int i = 0; i < 4; ++i)
      EXPECT_NEAR(sresp.filtered().probabilities(i), iresp.filtered(n).probabilities(i), 1e-9);
    ++n;
  }
  EXPECT_TRUE(stream->Finish().ok());
  EXPECT_EQ(n, 120);

  // Evaluate.
  v1::EvaluateRequest ereq;
  ereq.set_model_id("planted");
  *ereq.mutable_sequences()->add_sequences() = ToProto(test_);
  v1::EvaluateResponse eresp;
  ASSERT_TRUE(stub_->Evaluate(Ctx().get(), ereq, &eresp).ok());
  EXPECT_EQ(eresp.steps(), 120u);
  EXPECT_TRUE(std::isfinite(eresp.crf_ll_per_step()));
  EXPECT_TRUE(std::isfinite(eresp.hmm_ll_per_step()));

  // GetModel / ListModels.
  v1::GetModelRequest greq;
  greq.set_model_id("planted");
  greq.set_include_parameters(true);
  v1::GetModelResponse gresp;
  ASSERT_TRUE(stub_->GetModel(Ctx().get(), greq, &gresp).ok());
  EXPECT_EQ(gresp.parameters().transition_probabilities_size(), 16);
  EXPECT_EQ(gresp.info().description(), "planted");
  std::vector<v1::TrainResponse> again;
  EXPECT_EQ(TrainModel("planted", false, &again).error_code(), grpc::StatusCode::ALREADY_EXISTS);
  again.clear();
  ASSERT_TRUE(TrainModel("planted", true, &again).ok());
  v1::ListModelsRequest lreq;
  lreq.set_all_versions(true);
  v1::ListModelsResponse lresp;
  ASSERT_TRUE(stub_->ListModels(Ctx().get(), lreq, &lresp).ok());
  ASSERT_EQ(lresp.models_size(), 2);
  EXPECT_EQ(lresp.models(1).version(), 2u);
}

TEST_F(InferenceServiceTest, BadInputGivesClearErrors) {
  v1::InferRequest ireq;
  ireq.set_model_id("missing");
  *ireq.mutable_inputs() = ToProto(test_).inputs();
  v1::InferResponse iresp;
  auto st = stub_->Infer(Ctx().get(), ireq, &iresp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(st.error_message().find("missing"), std::string::npos);

  std::vector<v1::TrainResponse> progress;
  ASSERT_TRUE(TrainModel("m", false, &progress).ok());
  ireq.set_model_id("m");
  ireq.mutable_inputs(3)->set_intensity_mean_db(std::nan(""));
  st = stub_->Infer(Ctx().get(), ireq, &iresp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("inputs[3].intensity_mean_db"), std::string::npos) << st.error_message();
  ireq.clear_inputs();
  EXPECT_EQ(stub_->Infer(Ctx().get(), ireq, &iresp).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  v1::EvaluateRequest ereq;
  ereq.set_model_id("m");
  auto seq = ToProto(test_);
  seq.mutable_outputs()->RemoveLast();
  *ereq.mutable_sequences()->add_sequences() = seq;
  v1::EvaluateResponse eresp;
  st = stub_->Evaluate(Ctx().get(), ereq, &eresp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("outputs"), std::string::npos) << st.error_message();

  ereq.clear_sequences();
  ereq.set_corpus_dir("somewhere");
  EXPECT_EQ(stub_->Evaluate(Ctx().get(), ereq, &eresp).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);

  // A stream that starts without a config, and one with NaN features.
  {
    auto ctx = Ctx();
    auto stream = stub_->StreamInfer(ctx.get());
    v1::StreamInferRequest r;
    r.mutable_features()->set_length_s(0.2);
    stream->Write(r);
    stream->WritesDone();
    v1::StreamInferResponse resp;
    while (stream->Read(&resp)) {
    }
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  }
  {
    auto ctx = Ctx();
    auto stream = stub_->StreamInfer(ctx.get());
    v1::StreamInferRequest r;
    r.mutable_config()->set_model_id("m");
    stream->Write(r);
    r.mutable_features()->set_length_s(std::nan(""));
    stream->Write(r);
    stream->WritesDone();
    v1::StreamInferResponse resp;
    while (stream->Read(&resp)) {
    }
    const auto fin = stream->Finish();
    EXPECT_EQ(fin.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(fin.error_message().find("features[0].length_s"), std::string::npos) << fin.error_message();
  }
  v1::TrainRequest treq;
  treq.set_model_id("Bad Id");
  grpc::ClientContext tctx;
  auto reader = stub_->Train(&tctx, treq);
  v1::TrainResponse tr;
  while (reader->Read(&tr)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

}  // namespace
}  // namespace kinemo::inference
