// In-process tests of the inference gRPC service: train on planted data,
// infer, stream, evaluate, list, and the error mapping; the artifact RPCs
// over its store: a pushed model is served by the id it was pushed with (not
// the id inside the file), versions and deletion, and every bad push answers
// the right code naming the field and stores nothing.
#include "services/inference/inference_service.h"

#include <functional>
#include <filesystem>
#include <random>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "common/server/service_host.h"
#include "tests/unit/inference/planted.h"

namespace kinemo::inference {
namespace {

namespace fs = std::filesystem;
namespace cv1 = ::kinemo::common::v1;

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

  // Sends the messages as they are; returns the call's status.
  grpc::Status PushRaw(const std::vector<cv1::PushArtifactRequest>& messages, cv1::PushArtifactResponse* response) {
    auto ctx = Ctx();
    auto writer = stub_->PushArtifact(ctx.get(), response);
    for (const auto& m : messages) {
      if (!writer->Write(m)) break;
    }
    writer->WritesDone();
    return writer->Finish();
  }

  static cv1::PushArtifactRequest Header(const std::string& kind, const std::string& id,
                                         const std::vector<std::pair<std::string, std::uint64_t>>& files,
                                         bool overwrite = false) {
    cv1::PushArtifactRequest r;
    auto* h = r.mutable_header();
    h->mutable_ref()->set_kind(kind);
    h->mutable_ref()->set_id(id);
    h->set_overwrite(overwrite);
    for (const auto& [name, size] : files) {
      auto* f = h->add_files();
      f->set_name(name);
      f->set_size_bytes(size);
    }
    return r;
  }
  static cv1::PushArtifactRequest Chunk(std::uint32_t file, std::uint64_t offset, std::string data) {
    cv1::PushArtifactRequest r;
    r.mutable_chunk()->set_file_index(file);
    r.mutable_chunk()->set_offset(offset);
    r.mutable_chunk()->set_data(std::move(data));
    return r;
  }

  // A well-formed push of `bytes` as model.kmodel, in chunks of 1000 bytes.
  grpc::Status PushModel(const std::string& id, const std::string& bytes, bool overwrite,
                         cv1::PushArtifactResponse* response) {
    std::vector<cv1::PushArtifactRequest> m = {Header("models", id, {{"model.kmodel", bytes.size()}}, overwrite)};
    for (std::size_t off = 0; off < bytes.size(); off += 1000) m.push_back(Chunk(0, off, bytes.substr(off, 1000)));
    return PushRaw(m, response);
  }

  v1::InferResponse Infer(const std::string& id, grpc::Status* status) {
    v1::InferRequest req;
    req.set_model_id(id);
    *req.mutable_inputs() = ToProto(test_).inputs();
    v1::InferResponse resp;
    *status = stub_->Infer(Ctx().get(), req, &resp);
    return resp;
  }

  // A model trained elsewhere and written with an id of its own.
  std::string ModelBytes() {
    ModelTrainParams p;
    p.num_states = 3;
    p.window = 2;
    p.num_clusters = 3;
    p.hmm_restarts = 1;
    TrainReport report;
    auto model = RemappedModel::Train(train_, p, nullptr, &report);
    EXPECT_TRUE(model.ok()) << model.status();
    v1::ModelInfo info = MakeModelInfo(*model, p, report, 2, "trained elsewhere");
    info.set_model_id("the-id-inside-the-file");
    info.set_version(9);
    std::string bytes;
    EXPECT_TRUE(EncodeModel(*model, info).SerializeToString(&bytes));
    return bytes;
  }

  int Stored() {
    cv1::ListArtifactsRequest req;
    req.set_all_versions(true);
    cv1::ListArtifactsResponse resp;
    EXPECT_TRUE(stub_->ListArtifacts(Ctx().get(), req, &resp).ok());
    return resp.artifacts_size();
  }
  bool StagingEmpty() { return fs::is_empty(dir_ / ".staging"); }

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
  // Finite but far outside any speech: refused naming the field, not left to
  // overflow the CRF's features (it used to answer INTERNAL "no support").
  for (double db : {1e308, -1e308, 201.0}) {
    ireq.mutable_inputs(3)->set_intensity_mean_db(db);
    st = stub_->Infer(Ctx().get(), ireq, &iresp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << db;
    EXPECT_EQ(st.error_message().rfind("inputs[3].intensity_mean_db: ", 0), 0u) << st.error_message();
  }
  ireq.mutable_inputs(3)->set_intensity_mean_db(60.0);
  ireq.mutable_inputs(4)->set_length_s(1e9);
  st = stub_->Infer(Ctx().get(), ireq, &iresp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message().rfind("inputs[4].length_s: ", 0), 0u) << st.error_message();
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

  // Parameters: named as the request's fields, large uint32 values printed
  // as sent (a cast to int used to show 4294967295 as -1).
  const std::vector<std::pair<std::function<void(v1::TrainParams*)>, std::string>> params = {
      {[](v1::TrainParams* p) { p->set_num_states(4294967295u); }, "params.num_states: 4294967295 is too large"},
      {[](v1::TrainParams* p) { p->set_num_states(500); }, "params.num_states: 500 is outside 2..200"},
      {[](v1::TrainParams* p) { p->set_crf_max_iterations(2000000000u); },
       "params.crf_max_iterations: 2000000000 is outside 1..100000"},
  };
  for (const auto& [set, expected] : params) {
    treq.set_model_id("m2");
    set(treq.mutable_params());
    grpc::ClientContext pctx;
    auto preader = stub_->Train(&pctx, treq);
    while (preader->Read(&tr)) {
    }
    const grpc::Status st = preader->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << expected;
    EXPECT_EQ(st.error_message(), expected);
    treq.clear_params();
  }
}

TEST_F(InferenceServiceTest, PushedModelIsServedByThePushedId) {
  const std::string model_bytes = ModelBytes();
  cv1::PushArtifactResponse pushed;
  ASSERT_TRUE(PushModel("called-by", model_bytes, false, &pushed).ok());
  EXPECT_EQ(pushed.artifact().ref().kind(), "models");
  EXPECT_EQ(pushed.artifact().ref().id(), "called-by");
  EXPECT_EQ(pushed.artifact().ref().version(), 1u);
  ASSERT_EQ(pushed.artifact().files_size(), 1);
  EXPECT_EQ(pushed.artifact().files(0).name(), "model.kmodel");
  EXPECT_NE(pushed.artifact().summary_json().find("\"num_states\":3"), std::string::npos);
  EXPECT_TRUE(fs::exists(dir_ / "models" / "called-by" / "1" / "model.kmodel"));

  // Regression: ListModels reported the id stored inside the file.
  v1::ListModelsResponse models;
  ASSERT_TRUE(stub_->ListModels(Ctx().get(), v1::ListModelsRequest(), &models).ok());
  ASSERT_EQ(models.models_size(), 1);
  EXPECT_EQ(models.models(0).model_id(), "called-by");
  EXPECT_EQ(models.models(0).version(), 1u);
  v1::GetModelRequest greq;
  greq.set_model_id("called-by");
  v1::GetModelResponse gresp;
  ASSERT_TRUE(stub_->GetModel(Ctx().get(), greq, &gresp).ok());
  EXPECT_EQ(gresp.info().model_id(), "called-by");
  EXPECT_EQ(gresp.info().description(), "trained elsewhere");
  grpc::Status s;
  v1::InferResponse inferred = Infer("called-by", &s);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(inferred.model().model_id(), "called-by");
  EXPECT_EQ(inferred.smoothed_size(), static_cast<int>(test_.inputs.size()));

  // Same id without overwrite: refused; with overwrite: version 2 is served.
  EXPECT_EQ(PushModel("called-by", model_bytes, false, &pushed).error_code(), grpc::StatusCode::ALREADY_EXISTS);
  ASSERT_TRUE(PushModel("called-by", model_bytes, true, &pushed).ok());
  EXPECT_EQ(pushed.artifact().ref().version(), 2u);
  EXPECT_EQ(Infer("called-by", &s).model().version(), 2u);

  cv1::ListArtifactsRequest lreq;
  lreq.set_kind("models");
  lreq.set_all_versions(true);
  cv1::ListArtifactsResponse listed;
  ASSERT_TRUE(stub_->ListArtifacts(Ctx().get(), lreq, &listed).ok());
  ASSERT_EQ(listed.artifacts_size(), 2);
  EXPECT_FALSE(listed.in_memory());

  // Deleting the newest version serves the previous one; deleting all unloads.
  cv1::DeleteArtifactRequest dreq;
  dreq.mutable_ref()->set_kind("models");
  dreq.mutable_ref()->set_id("called-by");
  dreq.mutable_ref()->set_version(2);
  cv1::DeleteArtifactResponse deleted;
  ASSERT_TRUE(stub_->DeleteArtifact(Ctx().get(), dreq, &deleted).ok());
  ASSERT_EQ(deleted.deleted_size(), 1);
  EXPECT_EQ(Infer("called-by", &s).model().version(), 1u);
  dreq.mutable_ref()->set_version(0);
  ASSERT_TRUE(stub_->DeleteArtifact(Ctx().get(), dreq, &deleted).ok());
  Infer("called-by", &s);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  s = stub_->DeleteArtifact(Ctx().get(), dreq, &deleted);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(s.error_message().rfind("ref.id: ", 0), 0u) << s.error_message();
  EXPECT_EQ(Stored(), 0);
}

TEST_F(InferenceServiceTest, BadPushesNameTheFieldAndStoreNothing) {
  const std::string m = ModelBytes();
  const std::uint64_t n = m.size();
  struct Case {
    const char* what;
    std::vector<cv1::PushArtifactRequest> messages;
    grpc::StatusCode code;
    const char* field;
  };
  std::string garbage(n, '\0');
  for (std::size_t i = 0; i < garbage.size(); ++i) garbage[i] = static_cast<char>((i * 131 + 7) & 0xff);
  const std::vector<Case> cases = {
      {"a kind the service does not own",
       {Header("cubes", "m", {{"model.kmodel", n}}), Chunk(0, 0, m)},
       grpc::StatusCode::INVALID_ARGUMENT, "header.ref.kind: "},
      {"a bad id", {Header("models", "Bad Id!", {{"model.kmodel", n}}), Chunk(0, 0, m)},
       grpc::StatusCode::INVALID_ARGUMENT, "header.ref.id: "},
      {"another file name", {Header("models", "m", {{"weights.bin", n}}), Chunk(0, 0, m)},
       grpc::StatusCode::INVALID_ARGUMENT, "header.files: "},
      {"a path outside the version", {Header("models", "m", {{"../model.kmodel", n}})},
       grpc::StatusCode::INVALID_ARGUMENT, "header.files[0].name: "},
      {"offsets out of order",
       {Header("models", "m", {{"model.kmodel", n}}), Chunk(0, 100, m.substr(100)), Chunk(0, 0, m.substr(0, 100))},
       grpc::StatusCode::INVALID_ARGUMENT, "chunk.offset: "},
      {"a file shorter than declared",
       {Header("models", "m", {{"model.kmodel", n}}), Chunk(0, 0, m.substr(0, n / 2))},
       grpc::StatusCode::INVALID_ARGUMENT, "header.files[0]: "},
      {"a file longer than declared",
       {Header("models", "m", {{"model.kmodel", n}}), Chunk(0, 0, m + "x")},
       grpc::StatusCode::INVALID_ARGUMENT, "chunk.data: "},
      {"a chunk for a file not in the header",
       {Header("models", "m", {{"model.kmodel", n}}), Chunk(3, 0, m)},
       grpc::StatusCode::INVALID_ARGUMENT, "chunk.file_index: "},
      {"a corrupt model", {Header("models", "m", {{"model.kmodel", n}}), Chunk(0, 0, garbage)},
       grpc::StatusCode::INVALID_ARGUMENT, "header.files[0]: "},
      {"data before the header", {Chunk(0, 0, m)}, grpc::StatusCode::INVALID_ARGUMENT, "header: "},
      {"no message at all", {}, grpc::StatusCode::INVALID_ARGUMENT, "header: "},
  };
  for (const Case& c : cases) {
    cv1::PushArtifactResponse response;
    const grpc::Status s = PushRaw(c.messages, &response);
    EXPECT_EQ(s.error_code(), c.code) << c.what << ": " << s.error_message();
    EXPECT_EQ(s.error_message().rfind(c.field, 0), 0u) << c.what << ": " << s.error_message();
    EXPECT_EQ(Stored(), 0) << c.what;
    EXPECT_TRUE(StagingEmpty()) << c.what;
  }
  // Over the size limit: RESOURCE_EXHAUSTED before any data.
  cv1::PushArtifactResponse response;
  const grpc::Status big = PushRaw({Header("models", "m", {{"model.kmodel", 2ull << 30}})}, &response);
  EXPECT_EQ(big.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << big.error_message();
  EXPECT_EQ(Stored(), 0);

  cv1::ListArtifactsRequest lreq;
  lreq.set_kind("libraries");
  cv1::ListArtifactsResponse listed;
  const grpc::Status ls = stub_->ListArtifacts(Ctx().get(), lreq, &listed);
  EXPECT_EQ(ls.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(ls.error_message().rfind("kind: ", 0), 0u) << ls.error_message();
  cv1::DeleteArtifactRequest dreq;
  dreq.mutable_ref()->set_kind("models");
  dreq.mutable_ref()->set_id("../etc");
  cv1::DeleteArtifactResponse deleted;
  const grpc::Status ds = stub_->DeleteArtifact(Ctx().get(), dreq, &deleted);
  EXPECT_EQ(ds.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(ds.error_message().rfind("ref.id: ", 0), 0u) << ds.error_message();
}

}  // namespace
}  // namespace kinemo::inference
