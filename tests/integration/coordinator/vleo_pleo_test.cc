// The Vleo -> Pleo scenario with real processes on loopback: pleo_sim (a
// Modbus-simulated Pleo), robot_bridge and coordinator. A client Vleo throws
// kisses until Pleo is happy, read back from the robot through the bridge;
// then one service at a time is killed and restarted mid-scenario, and the
// final state must still be right.
#include "tests/integration/coordinator/vleo_stack.h"

namespace kinemo::coordinator {
namespace {

using namespace vleo_test;

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
  ASSERT_TRUE(st.robots[0].sim->Stop(SIGKILL, 5s).ok());
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
  // Without a store_dir, sessions live in the coordinator's memory: the Vleo
  // opens again (durability_test.cc: with one, they come back).
  ASSERT_TRUE(st.Open("vleo", common::v1::EMOTION_NEUTRAL).ok());
  ASSERT_TRUE(st.Act("vleo", common::v1::ACTION_KISSES, 1.0).ok());
  EXPECT_TRUE(st.PleoShows(common::v1::EMOTION_HAPPY, 10s));
}

// Issue 16: after OpenSession + CloseSession, another client's
// SetEmotion(HAPPY, wait_applied) timed out and the robot was put back to the
// closed session's emotion (with reset_robot, to neutral) two seconds later.
TEST(VleoPleo, AClosedSessionNoLongerDrivesItsRobot) {
  Stack st;
  ASSERT_NO_FATAL_FAILURE(st.Start());  // resend_s 0.3
  for (const bool reset : {false, true}) {
    SCOPED_TRACE(reset ? "reset_robot" : "no reset");
    ASSERT_TRUE(st.Open("vleo", common::v1::EMOTION_ANGRY).ok());
    ASSERT_TRUE(st.PleoShows(common::v1::EMOTION_ANGRY, 10s));
    ASSERT_TRUE(st.Close("vleo", reset).ok());
    if (reset) {
      ASSERT_TRUE(st.PleoShows(common::v1::EMOTION_NEUTRAL, 10s));
    }
    // Another client drives the robot through the bridge.
    rb::SetEmotionRequest set;
    set.set_robot_id("pleo");
    set.set_emotion(common::v1::EMOTION_HAPPY);
    set.set_intensity(1.0);
    set.set_wait_applied(true);
    rb::SetEmotionResponse applied;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    const grpc::Status s = st.bridge_stub->SetEmotion(&ctx, set, &applied);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_TRUE(applied.applied());
    // For ten resend periods, nothing puts the robot back.
    const auto until = std::chrono::steady_clock::now() + 3s;
    while (std::chrono::steady_clock::now() < until) {
      rb::RobotStatus status;
      ASSERT_TRUE(st.Status("pleo", &status));
      ASSERT_EQ(status.commanded_emotion(), common::v1::EMOTION_HAPPY)
          << st.coordinator->process().ReadLog();
      std::this_thread::sleep_for(50ms);
    }
    EXPECT_TRUE(st.PleoShows(common::v1::EMOTION_HAPPY, 1s));
  }
}

}  // namespace
}  // namespace kinemo::coordinator
