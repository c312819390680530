// The coordinator as the front door, with the real binaries: a coordinator
// process in front of an inference process. ListArtifacts (unary),
// PushArtifact (client stream) and Train (server stream) go through it; a bad
// request's code and message come back as the inference service gave them; a
// deadline reaches the training; a call for the robot bridge, and one for a
// service without an endpoint, are refused naming the method or the option.
#include <gtest/gtest.h>

#include <grpcpp/grpcpp.h>

#include <thread>

#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/cli/artifact_client.h"
#include "tests/integration/stores/stores_fixture.h"

namespace kinemo::stores_test {
namespace {

using testing::ServiceProcess;
using testing::ServiceProcessOptions;
namespace iv1 = ::kinemo::inference::v1;
namespace cv1 = ::kinemo::common::v1;

std::unique_ptr<grpc::ClientContext> Ctx(int seconds = 60) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  return c;
}

class Forwarding : public ::testing::Test {
 protected:
  void SetUp() override {
    auto corpus = TinyCorpus(dir_.File("corpus"));
    ASSERT_TRUE(corpus.ok()) << corpus.status();
    corpus_ = *std::move(corpus);
    ASSERT_TRUE(WriteTinyModel(corpus_, dir_.File("tiny.kmodel"), "tiny").ok());
    std::ofstream(dir_.File("inference.textproto"))
        << "store_dir: \"" << dir_.File("store") << "\"\n"
        << "defaults { num_states: 3 window: 2 num_clusters: 3 hmm_restarts: 1 }\n";
    auto inference = ServiceProcess::Start({.binary = Binary("inference"),
                                            .args = {"--config", dir_.File("inference.textproto")},
                                            .health_service = iv1::InferenceService::service_full_name()});
    ASSERT_TRUE(inference.ok()) << inference.status();
    inference_ = *std::move(inference);
    // No planner endpoint: its calls are refused naming the option.
    std::ofstream(dir_.File("coordinator.textproto"))
        << "services { inference { address: \"" << inference_->address() << "\" } }\n";
    auto coordinator = ServiceProcess::Start(
        {.binary = Binary("coordinator"), .args = {"--config", dir_.File("coordinator.textproto")}});
    ASSERT_TRUE(coordinator.ok()) << coordinator.status();
    coordinator_ = *std::move(coordinator);
    front_ = iv1::InferenceService::NewStub(coordinator_->Channel());
    direct_ = iv1::InferenceService::NewStub(inference_->Channel());
  }

  iv1::TrainRequest TrainRequest(const std::string& id) {
    iv1::TrainRequest req;
    req.set_model_id(id);
    for (const auto& s : corpus_) *req.mutable_sequences()->add_sequences() = inference::ToProto(s);
    req.set_request_id("train-through-the-front-door");
    return req;
  }

  testing::TempDir dir_;
  std::vector<inference::PairedSequence> corpus_;
  std::unique_ptr<ServiceProcess> inference_, coordinator_;
  std::unique_ptr<iv1::InferenceService::Stub> front_, direct_;
};

TEST_F(Forwarding, ArtifactCallsAndTrainingGoThroughTheCoordinator) {
  // PushArtifact (client stream), as the CLI sends it, to the coordinator.
  cli::PushSpec spec;
  spec.kind = "models";
  spec.id = "pushed";
  spec.files = {{"model.kmodel", dir_.File("tiny.kmodel")}};
  auto pushed = cli::PushArtifact(coordinator_->Channel(), spec);
  ASSERT_TRUE(pushed.ok()) << pushed.status();
  EXPECT_EQ(pushed->artifact().ref().id(), "pushed");

  // Train (server stream): progress messages, then the stored model.
  auto ctx = Ctx(300);
  auto reader = front_->Train(ctx.get(), TrainRequest("trained"));
  iv1::TrainResponse msg;
  int progress = 0;
  iv1::ModelInfo stored;
  while (reader->Read(&msg)) {
    ++progress;
    if (msg.has_model()) stored = msg.model();
  }
  const grpc::Status trained = reader->Finish();
  ASSERT_TRUE(trained.ok()) << trained.error_message();
  EXPECT_GE(progress, 3);
  EXPECT_EQ(stored.model_id(), "trained");

  // ListArtifacts (unary) through the front door sees both.
  cv1::ListArtifactsRequest lreq;
  cv1::ListArtifactsResponse listed;
  ASSERT_TRUE(front_->ListArtifacts(Ctx().get(), lreq, &listed).ok());
  ASSERT_EQ(listed.artifacts_size(), 2);
  EXPECT_EQ(listed.artifacts(0).ref().id(), "pushed");
  EXPECT_EQ(listed.artifacts(1).ref().id(), "trained");
}

TEST_F(Forwarding, ErrorsComeBackAsTheServiceGaveThem) {
  // The same bad requests, directly and through the coordinator.
  iv1::InferRequest infer;
  infer.set_model_id("no-such-model");
  infer.add_inputs()->set_end_s(0.2);
  iv1::InferResponse iresp;
  const grpc::Status d1 = direct_->Infer(Ctx().get(), infer, &iresp);
  const grpc::Status f1 = front_->Infer(Ctx().get(), infer, &iresp);
  EXPECT_EQ(d1.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(f1.error_code(), d1.error_code());
  EXPECT_EQ(f1.error_message(), d1.error_message());

  cli::PushSpec spec;
  spec.kind = "models";
  spec.id = "Bad Id";
  spec.files = {{"model.kmodel", dir_.File("tiny.kmodel")}};
  const auto d2 = cli::PushArtifact(inference_->Channel(), spec);
  const auto f2 = cli::PushArtifact(coordinator_->Channel(), spec);
  EXPECT_EQ(d2.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(f2.status(), d2.status());
  EXPECT_NE(f2.status().message().find("header.ref.id"), std::string::npos) << f2.status();

  // A deadline far shorter than the training reaches the inference service:
  // its training stops, and nothing is stored.
  auto ctx = Ctx(0);
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(300));
  auto req = TrainRequest("too-slow");
  for (int copy = 0; copy < 200; ++copy) {
    for (const auto& s : corpus_) *req.mutable_sequences()->add_sequences() = inference::ToProto(s);
  }
  auto* p = req.mutable_params();
  p->set_num_states(30);
  p->set_window(4);
  p->set_num_clusters(10);
  p->set_hmm_restarts(10);
  p->set_hmm_tolerance(1e-12);
  p->set_crf_tolerance(1e-15);
  p->set_crf_max_iterations(1000);
  auto reader = front_->Train(ctx.get(), req);
  iv1::TrainResponse msg;
  while (reader->Read(&msg)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  // One training at a time (max_concurrent_trainings): once a small one is
  // admitted, the long one has ended; had the deadline not reached it, it
  // would have ended by storing its model.
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  grpc::Status probe;
  do {
    auto pctx = Ctx(60);
    auto preader = direct_->Train(pctx.get(), TrainRequest("probe"));
    while (preader->Read(&msg)) {
    }
    probe = preader->Finish();
    if (probe.error_code() != grpc::StatusCode::RESOURCE_EXHAUSTED) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));  // poll: the slot frees when the training stops
  } while (std::chrono::steady_clock::now() < until);
  ASSERT_TRUE(probe.ok()) << probe.error_message();
  cv1::ListArtifactsRequest lreq;
  lreq.set_id("too-slow");
  cv1::ListArtifactsResponse listed;
  ASSERT_TRUE(direct_->ListArtifacts(Ctx().get(), lreq, &listed).ok());
  EXPECT_EQ(listed.artifacts_size(), 0);
}

TEST_F(Forwarding, RobotBridgeAndUnconfiguredServicesAreRefused) {
  auto bridge = robot_bridge::v1::RobotBridgeService::NewStub(coordinator_->Channel());
  robot_bridge::v1::ListRobotsResponse robots;
  const grpc::Status b = bridge->ListRobots(Ctx().get(), robot_bridge::v1::ListRobotsRequest(), &robots);
  EXPECT_EQ(b.error_code(), grpc::StatusCode::UNIMPLEMENTED);
  EXPECT_NE(b.error_message().find("/kinemo.robot_bridge.v1.RobotBridgeService/ListRobots"), std::string::npos)
      << b.error_message();

  auto planner = planner::v1::PlannerService::NewStub(coordinator_->Channel());
  cv1::ListArtifactsResponse listed;
  const grpc::Status p = planner->ListArtifacts(Ctx().get(), cv1::ListArtifactsRequest(), &listed);
  EXPECT_EQ(p.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(p.error_message().rfind("services.planner.address: ", 0), 0u) << p.error_message();

  // The CLI's `artifacts ls` through the coordinator: the inference service
  // answers; the planner and the cube tracker are reported, not fatal.
  std::string out, err;
  ASSERT_EQ((RunKinemo({"artifacts", "ls", "--server", coordinator_->address()}, &out, &err)), 0) << err;
  EXPECT_NE(err.find("services.planner.address"), std::string::npos) << err;
}

}  // namespace
}  // namespace kinemo::stores_test
