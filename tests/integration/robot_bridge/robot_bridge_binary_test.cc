// robot_bridge and pleo_sim as real processes on ephemeral loopback ports.
#include <signal.h>

#include <fstream>

#include <grpcpp/grpcpp.h>

#include "common/testing/process.h"
#include "gtest/gtest.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "tests/integration/robot_bridge/process_util.h"

namespace kinemo::robot_bridge {
namespace {

namespace v1 = ::kinemo::robot_bridge::v1;
using kinemo::testing::ChildProcess;
using kinemo::testing::ServiceProcess;

const std::string kBin = KINEMO_BINARY_DIR;

struct Stack {
  kinemo::testing::TempDir dir;
  std::unique_ptr<ChildProcess> sim;
  int sim_port = 0;
  std::unique_ptr<ServiceProcess> bridge;
  std::unique_ptr<v1::RobotBridgeService::Stub> stub;

  void StartSim() {
    std::string pf = dir.File("sim.port");
    std::remove(pf.c_str());
    auto s = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp",
                                  "127.0.0.1:" + std::to_string(sim_port), "--port-file", pf,
                                  "--switch-ms", "100"},
                                 dir.File("sim.log"));
    ASSERT_TRUE(s.ok()) << s.status();
    sim = std::move(*s);
    sim_port = robot::testing::WaitForPortFile(pf);
    ASSERT_GT(sim_port, 0) << sim->ReadLog();
  }
  void StartBridge() {
    std::string cfg = dir.File("rb.textproto");
    // A short grace: after a callback RPC over TCP, gRPC 1.51's Shutdown
    // waits out the whole grace period (seen with the common ServiceHost).
    std::ofstream(cfg) << "server { shutdown_grace_s: 0.5 }\n"
                       << "robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: "
                       << sim_port << " } timing { poll_s: 0.05 } }\n";
    auto b = ServiceProcess::Start({.binary = kBin + "/services/robot_bridge/robot_bridge",
                                    .args = {"--config", cfg},
                                    .health_service = v1::RobotBridgeService::service_full_name()});
    ASSERT_TRUE(b.ok()) << b.status();
    bridge = std::move(*b);
    stub = v1::RobotBridgeService::NewStub(bridge->Channel());
  }
  grpc::Status Set(int emotion, bool wait, v1::SetEmotionResponse* resp) {
    v1::SetEmotionRequest req;
    req.set_robot_id("pleo");
    req.set_emotion(static_cast<common::v1::Emotion>(emotion));
    req.set_intensity(0.6);
    req.set_wait_applied(wait);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
    return stub->SetEmotion(&ctx, req, resp);
  }
};

TEST(RobotBridgeBinary, SetEmotionReachesPleoSimAndSurvivesABridgeRestart) {
  Stack st;
  ASSERT_NO_FATAL_FAILURE(st.StartSim());
  ASSERT_NO_FATAL_FAILURE(st.StartBridge());
  v1::SetEmotionResponse resp;
  grpc::Status s = st.Set(common::v1::EMOTION_HAPPY, true, &resp);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_TRUE(resp.shown());
  auto regs = robot::testing::ParseMbpoll(robot::testing::Run(
      "/usr/bin/mbpoll -m tcp -p " + std::to_string(st.sim_port) + " -a 1 -0 -1 -t 3 -r 0 -c 3 127.0.0.1"));
  ASSERT_EQ(regs.size(), 3u);
  EXPECT_EQ(regs[0].second, 1);  // register value of happy
  EXPECT_EQ(regs[1].second, 600);
  const uint32_t first_seq = resp.sequence_number();

  // A new bridge process continues the robot's numbering.
  ASSERT_TRUE(st.bridge->Stop().ok());
  ASSERT_NO_FATAL_FAILURE(st.StartBridge());
  s = st.Set(common::v1::EMOTION_ANGRY, true, &resp);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(resp.sequence_number(), first_seq + 1);
  EXPECT_EQ(resp.status().shown_emotion(), common::v1::EMOTION_ANGRY);
}

TEST(RobotBridgeBinary, RobotRestartIsReportedAndRecovered) {
  Stack st;
  ASSERT_NO_FATAL_FAILURE(st.StartSim());
  ASSERT_NO_FATAL_FAILURE(st.StartBridge());
  v1::SetEmotionResponse resp;
  ASSERT_TRUE(st.Set(common::v1::EMOTION_ANGRY, true, &resp).ok());
  ASSERT_TRUE(st.sim->Stop(SIGKILL, std::chrono::seconds(5)).ok());
  // While the robot is gone: UNAVAILABLE, and the status says so.
  grpc::Status s = st.Set(common::v1::EMOTION_NEUTRAL, false, &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE) << s.error_message();
  v1::GetStatusRequest req;
  req.set_robot_id("pleo");
  v1::RobotStatus status;
  {
    grpc::ClientContext ctx;
    EXPECT_EQ(st.stub->GetStatus(&ctx, req, &status).error_code(), grpc::StatusCode::UNAVAILABLE);
  }
  ASSERT_NO_FATAL_FAILURE(st.StartSim());  // same port, empty registers
  // The bridge re-sends the last command (neutral) without being asked.
  EXPECT_TRUE(robot::testing::WaitUntil([&] {
    grpc::ClientContext ctx;
    return st.stub->GetStatus(&ctx, req, &status).ok() && status.in_sync() &&
           status.shown_emotion() == common::v1::EMOTION_NEUTRAL;
  })) << status.DebugString();
  EXPECT_GE(status.resends(), 1u);
}

}  // namespace
}  // namespace kinemo::robot_bridge
