// The Vleo -> Pleo scenario with real processes on loopback: pleo_sim (a
// Modbus-simulated Pleo), robot_bridge and coordinator. A client Vleo throws
// kisses until Pleo is happy, read back from the robot through the bridge;
// then one service at a time is killed and restarted mid-scenario, and the
// final state must still be right.
#include <signal.h>

#include <chrono>
#include <fstream>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "common/testing/process.h"
#include "gtest/gtest.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
namespace rb = ::kinemo::robot_bridge::v1;
using kinemo::testing::ChildProcess;
using kinemo::testing::ServiceProcess;
using namespace std::chrono_literals;

const std::string kBin = KINEMO_BINARY_DIR;

// Waits for a port file written by a child (checking that it lives).
int WaitForPortFile(const std::string& path, ChildProcess* child) {
  const auto until = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < until) {
    std::ifstream in(path);
    int port = 0;
    if (in >> port && port > 0) return port;
    if (!child->Running()) return -1;
    std::this_thread::sleep_for(20ms);
  }
  return -1;
}

struct Stack {
  kinemo::testing::TempDir dir;
  std::unique_ptr<ChildProcess> sim;
  int sim_port = 0;
  std::unique_ptr<ChildProcess> bridge;
  int bridge_port = 0;
  std::unique_ptr<ServiceProcess> coordinator;
  std::unique_ptr<v1::CoordinatorService::Stub> stub;
  std::unique_ptr<rb::RobotBridgeService::Stub> bridge_stub;

  void StartSim() {
    const std::string pf = dir.File("sim.port");
    std::remove(pf.c_str());
    auto s = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp",
                                  "127.0.0.1:" + std::to_string(sim_port), "--port-file", pf,
                                  "--switch-ms", "100"},
                                 dir.File("sim.log"));
    ASSERT_TRUE(s.ok()) << s.status();
    sim = std::move(*s);
    sim_port = WaitForPortFile(pf, sim.get());
    ASSERT_GT(sim_port, 0) << sim->ReadLog();
  }
  void StartBridge() {
    const std::string cfg = dir.File("rb.textproto"), pf = dir.File("rb.port");
    std::remove(pf.c_str());
    std::ofstream(cfg) << "server { shutdown_grace_s: 0.5 }\n"
                       << "robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: "
                       << sim_port << " } timing { poll_s: 0.05 max_backoff_s: 0.2 } }\n";
    auto b = ChildProcess::Spawn({kBin + "/services/robot_bridge/robot_bridge", "--config", cfg,
                                  "--host", "127.0.0.1", "--port", std::to_string(bridge_port),
                                  "--port-file", pf},
                                 dir.File("rb.log"));
    ASSERT_TRUE(b.ok()) << b.status();
    bridge = std::move(*b);
    bridge_port = WaitForPortFile(pf, bridge.get());
    ASSERT_GT(bridge_port, 0) << bridge->ReadLog();
    auto channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(bridge_port),
                                       grpc::InsecureChannelCredentials());
    ASSERT_TRUE(kinemo::testing::WaitForServing(channel, "", 20s).ok());
    bridge_stub = rb::RobotBridgeService::NewStub(channel);
  }
  void StartCoordinator() {
    const std::string cfg = dir.File("coordinator.textproto");
    std::ofstream(cfg) << "server { shutdown_grace_s: 0.5 }\n"
                       << "services { robot_bridge { address: \"127.0.0.1:" << bridge_port
                       << "\" max_reconnect_backoff_s: 0.2 } }\n"
                       << "emotion { rate_per_s: 1.0 }\n"  // angry -> happy in 1.5 s
                       << "resend_s: 0.3\n";
    auto c = ServiceProcess::Start({.binary = kBin + "/services/coordinator/coordinator",
                                    .args = {"--config", cfg},
                                    .health_service = v1::CoordinatorService::service_full_name()});
    ASSERT_TRUE(c.ok()) << c.status();
    coordinator = std::move(*c);
    stub = v1::CoordinatorService::NewStub(coordinator->Channel());
  }
  void Start() {
    ASSERT_NO_FATAL_FAILURE(StartSim());
    ASSERT_NO_FATAL_FAILURE(StartBridge());
    ASSERT_NO_FATAL_FAILURE(StartCoordinator());
  }

  grpc::Status Open(const std::string& id, common::v1::Emotion initial) {
    v1::OpenSessionRequest r;
    r.set_session_id(id);
    r.set_robot_id("pleo");
    r.set_initial_emotion(initial);
    v1::OpenSessionResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    return stub->OpenSession(&ctx, r, &resp);
  }
  grpc::Status Act(const std::string& id, common::v1::Action action, double intensity) {
    v1::ActRequest r;
    r.set_session_id(id);
    r.set_action(action);
    r.set_intensity(intensity);
    v1::ActResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    return stub->Act(&ctx, r, &resp);
  }
  // Polls the bridge (which reads pleo_sim's registers) until Pleo shows `e`.
  bool PleoShows(common::v1::Emotion e, std::chrono::milliseconds timeout) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < until) {
      rb::GetStatusRequest r;
      r.set_robot_id("pleo");
      rb::RobotStatus st;
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + 1s);
      if (bridge_stub->GetStatus(&ctx, r, &st).ok() && st.connected() && st.shown_emotion() == e &&
          st.state() == rb::ROBOT_STATE_FOLLOWING) {
        return true;
      }
      std::this_thread::sleep_for(50ms);
    }
    return false;
  }
};

TEST(VleoPleo, KissesMakePleoHappyThroughTheWholeStack) {
  Stack st;
  ASSERT_NO_FATAL_FAILURE(st.Start());
  ASSERT_TRUE(st.Open("vleo", common::v1::EMOTION_ANGRY).ok());
  EXPECT_TRUE(st.PleoShows(common::v1::EMOTION_ANGRY, 10s));

  grpc::ClientContext watch;
  watch.set_deadline(std::chrono::system_clock::now() + 30s);
  v1::WatchSessionRequest w;
  w.set_session_id("vleo");
  auto reader = st.stub->WatchSession(&watch, w);
  ASSERT_TRUE(st.Act("vleo", common::v1::ACTION_KISSES, 1.0).ok());
  std::vector<std::pair<int, double>> emotions;
  std::vector<double> latencies_ms;
  v1::SessionEvent e;
  while (reader->Read(&e)) {
    if (e.has_emotion_changed()) {
      emotions.push_back({e.emotion_changed().to_emotion(), e.session_time_s()});
    }
    if (e.has_robot_commanded() && e.robot_commanded().error().empty()) {
      latencies_ms.push_back(e.robot_commanded().latency_ms());
      if (e.robot_commanded().emotion() == common::v1::EMOTION_HAPPY) break;
    }
  }
  watch.TryCancel();
  (void)reader->Finish();
  ASSERT_EQ(emotions.size(), 2u);
  EXPECT_EQ(emotions[0].first, common::v1::EMOTION_NEUTRAL);
  EXPECT_EQ(emotions[1].first, common::v1::EMOTION_HAPPY);
  EXPECT_NEAR(emotions[1].second - emotions[0].second, 0.8, 1e-6);  // -0.3 -> +0.5 at 1 /s
  EXPECT_FALSE(latencies_ms.empty());
  EXPECT_TRUE(st.PleoShows(common::v1::EMOTION_HAPPY, 10s)) << st.bridge->ReadLog();
}

TEST(VleoPleo, ARestartedRobotBridgeGetsTheSessionsEmotion) {
  Stack st;
  ASSERT_NO_FATAL_FAILURE(st.Start());
  ASSERT_TRUE(st.Open("vleo", common::v1::EMOTION_HAPPY).ok());
  ASSERT_TRUE(st.PleoShows(common::v1::EMOTION_HAPPY, 10s));
  // Kill the bridge hard; Pleo (no heartbeat) soon turns autonomous.
  ASSERT_TRUE(st.bridge->Stop(SIGKILL, 5s).ok());
  ASSERT_TRUE(st.Act("vleo", common::v1::ACTION_SHOUTING, 1.0).ok());  // angry in 1.5 s
  ASSERT_NO_FATAL_FAILURE(st.StartBridge());  // same port, knows no command
  EXPECT_TRUE(st.PleoShows(common::v1::EMOTION_ANGRY, 15s)) << st.coordinator->process().ReadLog();
  v1::GetSessionRequest g;
  g.set_session_id("vleo");
  v1::Session s;
  grpc::ClientContext ctx;
  ASSERT_TRUE(st.stub->GetSession(&ctx, g, &s).ok());
  EXPECT_EQ(s.emotion(), common::v1::EMOTION_ANGRY);
  EXPECT_TRUE(s.robot_connected());
}

TEST(VleoPleo, ARestartedPleoSimEndsInTheRightState) {
  Stack st;
  ASSERT_NO_FATAL_FAILURE(st.Start());
  ASSERT_TRUE(st.Open("vleo", common::v1::EMOTION_ANGRY).ok());
  ASSERT_TRUE(st.PleoShows(common::v1::EMOTION_ANGRY, 10s));
  ASSERT_TRUE(st.sim->Stop(SIGKILL, 5s).ok());
  ASSERT_TRUE(st.Act("vleo", common::v1::ACTION_KISSES, 1.0).ok());  // happy in 1.5 s
  ASSERT_NO_FATAL_FAILURE(st.StartSim());  // same port, a robot that starts neutral
  EXPECT_TRUE(st.PleoShows(common::v1::EMOTION_HAPPY, 15s));
}

TEST(VleoPleo, ARestartedCoordinatorCanBeUsedAgainRightAway) {
  Stack st;
  ASSERT_NO_FATAL_FAILURE(st.Start());
  ASSERT_TRUE(st.Open("vleo", common::v1::EMOTION_ANGRY).ok());
  ASSERT_TRUE(st.PleoShows(common::v1::EMOTION_ANGRY, 10s));
  ASSERT_TRUE(st.coordinator->Stop().ok());
  ASSERT_NO_FATAL_FAILURE(st.StartCoordinator());
  // Sessions live in the coordinator's memory: the Vleo opens again.
  ASSERT_TRUE(st.Open("vleo", common::v1::EMOTION_NEUTRAL).ok());
  ASSERT_TRUE(st.Act("vleo", common::v1::ACTION_KISSES, 1.0).ok());
  EXPECT_TRUE(st.PleoShows(common::v1::EMOTION_HAPPY, 10s));
}

}  // namespace
}  // namespace kinemo::coordinator
