// Sessions on a fake clock: events with timestamps, robot commands, errors.
#include "services/coordinator/core/session_manager.h"

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include <algorithm>

#include "gtest/gtest.h"

namespace kinemo::coordinator {
namespace {

using common::v1::ACTION_KISSES;
using common::v1::ACTION_SHOUTING;
using common::v1::EMOTION_ANGRY;
using common::v1::EMOTION_HAPPY;
using common::v1::EMOTION_NEUTRAL;

struct Fixture {
  FakeClock clock;
  std::vector<RobotCommand> commands;
  std::vector<v1::SessionEvent> events;
  SessionManager manager;
  explicit Fixture(SessionManagerOptions o = Options())
      : manager(o, &clock, [this](const RobotCommand& c) { commands.push_back(c); }) {}
  static SessionManagerOptions Options() {
    SessionManagerOptions o;
    o.emotion = *ResolveEmotionParams(v1::EmotionModelOptions());
    return o;
  }
  v1::Session Open(const std::string& id, const std::string& robot, common::v1::Emotion e) {
    v1::OpenSessionRequest r;
    r.set_session_id(id);
    r.set_robot_id(robot);
    r.set_initial_emotion(e);
    auto s = manager.Open(r);
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? *s : v1::Session();
  }
};

TEST(SessionManager, KissesMakeAnAngryPleoHappyWithTimedEvents) {
  Fixture f;
  f.Open("vleo-1", "pleo", EMOTION_ANGRY);
  ASSERT_EQ(f.commands.size(), 1u);  // the initial emotion
  EXPECT_EQ(f.commands[0].emotion, EMOTION_ANGRY);
  ASSERT_TRUE(f.manager.Subscribe("vleo-1", [&](const v1::SessionEvent& e) {
    f.events.push_back(e);
  }).ok());
  ASSERT_EQ(f.events.size(), 1u);
  EXPECT_TRUE(f.events[0].has_snapshot());
  EXPECT_EQ(f.events[0].snapshot().emotion(), EMOTION_ANGRY);

  f.clock.Advance(2.0);
  ASSERT_TRUE(f.manager.Act("vleo-1", ACTION_KISSES, 1.0, false).ok());
  EXPECT_NEAR(f.manager.NextChangeTime() - f.clock.MonotonicS(), 7.0, 1e-9);
  // Ticks at an irregular period: event times stay exact.
  for (int i = 0; i < 50; ++i) {
    f.clock.Advance(0.37);
    f.manager.Tick();
  }
  std::vector<v1::SessionEvent> emotions;
  for (const auto& e : f.events) {
    if (e.has_emotion_changed()) emotions.push_back(e);
  }
  ASSERT_EQ(emotions.size(), 2u);
  EXPECT_EQ(emotions[0].emotion_changed().to_emotion(), EMOTION_NEUTRAL);
  EXPECT_NEAR(emotions[0].session_time_s(), 9.0, 1e-6);
  EXPECT_EQ(emotions[1].emotion_changed().to_emotion(), EMOTION_HAPPY);
  EXPECT_NEAR(emotions[1].session_time_s(), 17.0, 1e-6);
  EXPECT_EQ(emotions[1].emotion_changed().action(), ACTION_KISSES);
  // The wall timestamp follows the session time.
  const auto& open = f.events[0].event_time();
  EXPECT_NEAR((emotions[1].event_time().seconds() - open.seconds()) +
                  (emotions[1].event_time().nanos() - open.nanos()) * 1e-9,
              17.0, 1e-6);
  ASSERT_EQ(f.commands.size(), 3u);
  EXPECT_EQ(f.commands[2].emotion, EMOTION_HAPPY);
  EXPECT_EQ(f.commands[2].robot_id, "pleo");
  auto s = f.manager.Get("vleo-1");
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->emotion(), EMOTION_HAPPY);
  EXPECT_NEAR(s->session_time_s(), 2.0 + 50 * 0.37, 1e-6);
}

TEST(SessionManager, ManySessionsRunIndependently) {
  Fixture f;
  for (int i = 0; i < 1000; ++i) {
    f.Open(absl::StrCat("s", i), absl::StrCat("pleo-", i % 10),
           i % 2 ? EMOTION_ANGRY : EMOTION_HAPPY);
  }
  for (int i = 0; i < 1000; ++i) {
    ASSERT_TRUE(f.manager
                    .Act(absl::StrCat("s", i), i % 2 ? ACTION_KISSES : ACTION_SHOUTING, 1.0,
                         false)
                    .ok());
  }
  f.clock.Advance(16.0);
  f.manager.Tick();
  auto all = f.manager.List("");
  ASSERT_EQ(all.size(), 1000u);
  for (int i = 0; i < 1000; ++i) {
    EXPECT_EQ(all[i].session_id(), absl::StrCat("s", i));  // opening order
    EXPECT_EQ(all[i].emotion(), i % 2 ? EMOTION_HAPPY : EMOTION_ANGRY);
  }
  EXPECT_EQ(f.manager.List("pleo-3").size(), 100u);
}

TEST(SessionManager, ErrorsNameTheFieldAndChangeNothing) {
  SessionManagerOptions o = Fixture::Options();
  o.max_sessions = 2;
  o.exclusive_robots = true;
  Fixture f(o);
  f.Open("a", "pleo", EMOTION_NEUTRAL);
  v1::OpenSessionRequest r;
  r.set_session_id("a");
  r.set_robot_id("other");
  EXPECT_EQ(f.manager.Open(r).status().code(), absl::StatusCode::kAlreadyExists);
  r.set_session_id("b");
  r.set_robot_id("pleo");
  EXPECT_EQ(f.manager.Open(r).status().code(), absl::StatusCode::kAlreadyExists);
  r.set_session_id("Bad Id");
  r.set_robot_id("x");
  auto bad = f.manager.Open(r);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StartsWith(bad.status().message(), "session_id"));
  r.set_session_id("");
  r.set_robot_id("");
  EXPECT_TRUE(absl::StartsWith(f.manager.Open(r).status().message(), "robot_id"));
  r.set_robot_id("p2");
  auto generated = f.manager.Open(r);
  ASSERT_TRUE(generated.ok());
  EXPECT_FALSE(generated->session_id().empty());
  r.set_robot_id("p3");
  EXPECT_EQ(f.manager.Open(r).status().code(), absl::StatusCode::kResourceExhausted);

  auto act = f.manager.Act("a", common::v1::ACTION_UNSPECIFIED, 0, false);
  EXPECT_TRUE(absl::StartsWith(act.status().message(), "action"));
  act = f.manager.Act("a", ACTION_KISSES, 1.5, false);
  EXPECT_TRUE(absl::StartsWith(act.status().message(), "intensity"));
  EXPECT_EQ(f.manager.Act("zz", ACTION_KISSES, 0, false).status().code(),
            absl::StatusCode::kNotFound);
  EXPECT_EQ(f.manager.Get("a")->action(), common::v1::ACTION_IDLE);
}

TEST(SessionManager, CloseEndsTheWatchAndCanResetTheRobot) {
  Fixture f;
  f.Open("a", "pleo", EMOTION_HAPPY);
  ASSERT_TRUE(f.manager.Subscribe("", [&](const v1::SessionEvent& e) { f.events.push_back(e); })
                  .ok());
  f.commands.clear();
  auto closed = f.manager.Close("a", true, "client");
  ASSERT_TRUE(closed.ok());
  EXPECT_EQ(closed->emotion(), EMOTION_HAPPY);
  ASSERT_EQ(f.commands.size(), 1u);
  EXPECT_EQ(f.commands[0].emotion, EMOTION_NEUTRAL);
  ASSERT_FALSE(f.events.empty());
  EXPECT_EQ(f.events.back().session_closed().reason(), "client");
  EXPECT_EQ(f.manager.size(), 0u);
  EXPECT_EQ(f.manager.Get("a").status().code(), absl::StatusCode::kNotFound);
}

TEST(SessionManager, RobotStatusAndDesiredCommandsForResending) {
  Fixture f;
  f.Open("a", "pleo", EMOTION_ANGRY);
  f.clock.Advance(1);
  f.Open("b", "pleo", EMOTION_HAPPY);
  f.Open("c", "other", EMOTION_NEUTRAL);
  ASSERT_TRUE(f.manager.Subscribe("a", [&](const v1::SessionEvent& e) { f.events.push_back(e); })
                  .ok());
  f.manager.OnRobotStatus("pleo", true, EMOTION_HAPPY, 80);
  f.manager.OnRobotStatus("pleo", true, EMOTION_HAPPY, 80);  // no change: no event
  ASSERT_EQ(f.events.size(), 2u);
  EXPECT_TRUE(f.events[1].robot_status_changed().connected());
  EXPECT_TRUE(f.manager.Get("a")->robot_connected());
  auto desired = f.manager.DesiredCommands("pleo");
  ASSERT_EQ(desired.size(), 2u);
  EXPECT_EQ(desired[0].session_id, "b");  // newest first
  EXPECT_EQ(desired[0].emotion, EMOTION_HAPPY);
  EXPECT_EQ(desired[1].emotion, EMOTION_ANGRY);
  EXPECT_TRUE(f.manager.DesiredCommands("nobody").empty());
}

}  // namespace
}  // namespace kinemo::coordinator

namespace kinemo::coordinator {
namespace {

TEST(SessionManager, IdleSessionsCloseUnlessWatchedOrActive) {
  SessionManagerOptions o = Fixture::Options();
  o.idle_timeout_s = 60;
  Fixture f(o);
  f.Open("quiet", "pleo", common::v1::EMOTION_NEUTRAL);
  f.Open("busy", "pleo", common::v1::EMOTION_NEUTRAL);
  f.Open("watched", "pleo", common::v1::EMOTION_NEUTRAL);
  auto sub = f.manager.Subscribe("watched", [&](const v1::SessionEvent& e) { f.events.push_back(e); });
  ASSERT_TRUE(sub.ok());
  f.clock.Advance(40);
  ASSERT_TRUE(f.manager.Act("busy", common::v1::ACTION_KISSES, 0, false).ok());
  f.clock.Advance(25);
  EXPECT_EQ(f.manager.Tick(), std::vector<std::string>{"quiet"});
  EXPECT_EQ(f.manager.size(), 2u);
  f.manager.Unsubscribe(*sub);
  f.clock.Advance(61);
  auto closed = f.manager.Tick();
  std::sort(closed.begin(), closed.end());
  EXPECT_EQ(closed, (std::vector<std::string>{"busy", "watched"}));
  EXPECT_EQ(f.manager.size(), 0u);
}

}  // namespace
}  // namespace kinemo::coordinator

namespace kinemo::coordinator {
namespace {

// The cube's first face and intensity (the tracker's first frame) are the
// attach's state: in AttachCube's answer, its event and later snapshots; a
// turn and the cube's Acts move them; DetachCube clears them.
TEST(SessionManager, TheCubesFirstFaceIsTheAttachsStateAndFollowsItsEvents) {
  Fixture f;
  f.Open("a", "pleo", EMOTION_NEUTRAL);
  ASSERT_TRUE(f.manager.Subscribe("a", [&](const v1::SessionEvent& e) { f.events.push_back(e); }).ok());
  cube_tracker::v1::VideoSource source;
  source.set_video_file("cube.avi");
  cube_tracker::v1::CubeState first;
  first.set_visible(true);
  first.set_top_face(cube_tracker::v1::CUBE_FACE_POS_Z);
  first.set_intensity(0.25);
  auto attached = f.manager.AttachCube("a", source, {}, &first);
  ASSERT_TRUE(attached.ok()) << attached.status();
  EXPECT_EQ(attached->cube_face(), cube_tracker::v1::CUBE_FACE_POS_Z);
  EXPECT_TRUE(attached->cube_visible());
  EXPECT_DOUBLE_EQ(attached->cube_intensity(), 0.25);
  ASSERT_TRUE(f.events.back().has_cube_status_changed());
  const v1::CubeStatusChanged& at_attach = f.events.back().cube_status_changed();
  EXPECT_TRUE(at_attach.attached());
  EXPECT_TRUE(at_attach.visible());
  EXPECT_EQ(at_attach.top_face(), cube_tracker::v1::CUBE_FACE_POS_Z);
  EXPECT_DOUBLE_EQ(at_attach.intensity(), 0.25);
  // A watcher subscribing now sees the face in its snapshot.
  std::vector<v1::SessionEvent> late;
  ASSERT_TRUE(f.manager.Subscribe("a", [&](const v1::SessionEvent& e) { late.push_back(e); }).ok());
  ASSERT_EQ(late.size(), 1u);
  EXPECT_EQ(late[0].snapshot().cube_face(), cube_tracker::v1::CUBE_FACE_POS_Z);

  ASSERT_TRUE(f.manager.Act("a", common::v1::ACTION_IDLE, 0.5, true).ok());
  EXPECT_DOUBLE_EQ(f.manager.Get("a")->cube_intensity(), 0.5);
  cube_tracker::v1::CubeEvent turn;
  turn.mutable_face_changed()->set_from_face(cube_tracker::v1::CUBE_FACE_POS_Z);
  turn.mutable_face_changed()->set_to_face(cube_tracker::v1::CUBE_FACE_POS_X);
  ASSERT_TRUE(f.manager.SetCubeVisible("a", true, turn).ok());
  EXPECT_EQ(f.events.back().cube_status_changed().top_face(), cube_tracker::v1::CUBE_FACE_POS_X);
  EXPECT_DOUBLE_EQ(f.events.back().cube_status_changed().intensity(), 0.0);  // a new face starts at 0
  EXPECT_EQ(f.manager.Get("a")->cube_face(), cube_tracker::v1::CUBE_FACE_POS_X);

  auto detached = f.manager.DetachCube("a", "");
  ASSERT_TRUE(detached.ok());
  EXPECT_EQ(detached->cube_face(), cube_tracker::v1::CUBE_FACE_UNSPECIFIED);
  EXPECT_FALSE(detached->cube_visible());
  EXPECT_FALSE(f.events.back().cube_status_changed().attached());

  // Without a first state (no frame tracked yet) the face is unknown until Found.
  ASSERT_TRUE(f.manager.AttachCube("a", source, {}).ok());
  EXPECT_EQ(f.events.back().cube_status_changed().top_face(), cube_tracker::v1::CUBE_FACE_UNSPECIFIED);
  cube_tracker::v1::CubeEvent found;
  found.mutable_found()->set_top_face(cube_tracker::v1::CUBE_FACE_NEG_Y);
  ASSERT_TRUE(f.manager.SetCubeVisible("a", true, found).ok());
  EXPECT_EQ(f.manager.Get("a")->cube_face(), cube_tracker::v1::CUBE_FACE_NEG_Y);
  EXPECT_TRUE(f.manager.Get("a")->cube_visible());
}

}  // namespace
}  // namespace kinemo::coordinator
