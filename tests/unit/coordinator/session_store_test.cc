// Durable sessions: the SessionManager on the SQLite store (and on a store
// that fails on demand), against a manager without a store on the same
// clock; the store's own errors for a corrupt or unusable store_dir.
#include <stdlib.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "absl/strings/match.h"
#include "gtest/gtest.h"
#include "services/coordinator/core/session_manager.h"
#include "services/coordinator/core/sqlite_session_store.h"

namespace kinemo::coordinator {
namespace {

using common::v1::ACTION_IDLE;
using common::v1::ACTION_KISSES;
using common::v1::ACTION_SHOUTING;
using common::v1::EMOTION_ANGRY;
using common::v1::EMOTION_HAPPY;
using common::v1::EMOTION_NEUTRAL;
using common::v1::EMOTION_UNSPECIFIED;

struct ScratchDir {
  std::string path;
  ScratchDir() {
    std::string t = (std::filesystem::temp_directory_path() / "kinemo-session-store-XXXXXX").string();
    path = ::mkdtemp(t.data()) != nullptr ? t : "";
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

SessionManagerOptions Options() {
  SessionManagerOptions o;
  o.emotion = *ResolveEmotionParams(v1::EmotionModelOptions());
  return o;
}

v1::OpenSessionRequest OpenRequest(const std::string& id, const std::string& robot,
                                   common::v1::Emotion e) {
  v1::OpenSessionRequest r;
  r.set_session_id(id);
  r.set_robot_id(robot);
  r.set_initial_emotion(e);
  r.set_vleo_name("vleo of " + id);
  return r;
}

// A store in memory that can be told to fail.
class FlakyStore final : public SessionStore {
 public:
  bool fail = false;
  std::map<std::string, StoredSession> rows;
  Status Put(const StoredSession& s) override {
    if (fail) return absl::UnavailableError("store_dir: disk full");
    rows[s.session_id] = s;
    return absl::OkStatus();
  }
  Status Delete(const std::string& id) override {
    if (fail) return absl::UnavailableError("store_dir: disk full");
    rows.erase(id);
    return absl::OkStatus();
  }
  StatusOr<std::vector<StoredSession>> LoadAll() override {
    std::vector<StoredSession> out;
    for (const auto& [id, s] : rows) out.push_back(s);
    return out;
  }
};

TEST(DurableSessions, ARestartedManagerGivesWhatANeverStoppedOneGives) {
  ScratchDir dir;
  ASSERT_FALSE(dir.path.empty());
  FakeClock clock;
  std::vector<RobotCommand> commands;
  // The reference: never stops, no store.
  SessionManager reference(Options(), &clock, nullptr);
  auto store = SqliteSessionStore::Open(dir.path);
  ASSERT_TRUE(store.ok()) << store.status();
  auto durable = std::make_unique<SessionManager>(Options(), &clock, nullptr, store->get());
  for (SessionManager* m : {&reference, durable.get()}) {
    ASSERT_TRUE(m->Open(OpenRequest("kiss", "pleo", EMOTION_ANGRY)).ok());
    ASSERT_TRUE(m->Open(OpenRequest("shout", "pleo-2", EMOTION_HAPPY)).ok());
    ASSERT_TRUE(m->Open(OpenRequest("gone", "pleo-3", EMOTION_NEUTRAL)).ok());
  }
  clock.Advance(1.5);
  for (SessionManager* m : {&reference, durable.get()}) {
    ASSERT_TRUE(m->Act("kiss", ACTION_KISSES, 0.25, false).ok());
    ASSERT_TRUE(m->Act("shout", ACTION_SHOUTING, 1.0, false).ok());
    ASSERT_TRUE(m->Close("gone", false, "client").ok());
  }
  clock.Advance(2.0);
  ASSERT_TRUE(durable->Act("kiss", ACTION_KISSES, 0.5, false).ok());
  ASSERT_TRUE(reference.Act("kiss", ACTION_KISSES, 0.5, false).ok());
  clock.Advance(0.25);
  // The coordinator dies (nothing is flushed or closed), and is down 14 s.
  durable.reset();
  store->reset();
  clock.Advance(14.0);
  auto reopened = SqliteSessionStore::Open(dir.path);
  ASSERT_TRUE(reopened.ok()) << reopened.status();
  SessionManager restarted(Options(), &clock, [&](const RobotCommand& c) { commands.push_back(c); },
                           reopened->get());
  auto cubes = restarted.Restore();
  ASSERT_TRUE(cubes.ok()) << cubes.status();
  EXPECT_TRUE(cubes->empty());
  auto want = reference.List("");
  auto got = restarted.List("");
  ASSERT_EQ(got.size(), 2u);
  ASSERT_EQ(want.size(), 2u);
  for (std::size_t i = 0; i < got.size(); ++i) {
    SCOPED_TRACE(got[i].session_id());
    EXPECT_EQ(got[i].session_id(), want[i].session_id());
    EXPECT_EQ(got[i].robot_id(), want[i].robot_id());
    EXPECT_EQ(got[i].vleo_name(), want[i].vleo_name());
    EXPECT_EQ(got[i].action(), want[i].action());
    EXPECT_EQ(got[i].intensity(), want[i].intensity());
    EXPECT_NEAR(got[i].valence(), want[i].valence(), 1e-6);
    EXPECT_EQ(got[i].emotion(), want[i].emotion());
    EXPECT_NEAR(got[i].session_time_s(), want[i].session_time_s(), 1e-6);
  }
  // Over the downtime, kisses at 0.5 took the angry Pleo to neutral (v 0.30);
  // 16.25 s of shouting made the happy one angry (v -0.625).
  EXPECT_EQ(got[0].emotion(), EMOTION_NEUTRAL);
  EXPECT_EQ(got[1].emotion(), EMOTION_ANGRY);
  // Each robot is told its session's emotion at once.
  ASSERT_EQ(commands.size(), 2u);
  EXPECT_EQ(commands[0].robot_id, "pleo");
  EXPECT_EQ(commands[0].emotion, EMOTION_NEUTRAL);
  EXPECT_EQ(commands[1].emotion, EMOTION_ANGRY);
  // The model goes on from there, as the reference does.
  clock.Advance(30);
  EXPECT_EQ(restarted.Get("kiss")->emotion(), reference.Get("kiss")->emotion());
  EXPECT_EQ(restarted.Get("kiss")->emotion(), EMOTION_HAPPY);
  // A new session's order follows the restored ones.
  ASSERT_TRUE(restarted.Open(OpenRequest("new", "pleo-4", EMOTION_NEUTRAL)).ok());
  EXPECT_EQ(restarted.List("").back().session_id(), "new");
}

TEST(DurableSessions, EveryAcknowledgedActIsCountedAndCubesAndRobotCommandsAreKept) {
  ScratchDir dir;
  FakeClock clock;
  {
    auto store = SqliteSessionStore::Open(dir.path);
    ASSERT_TRUE(store.ok()) << store.status();
    SessionManager m(Options(), &clock, nullptr, store->get());
    ASSERT_TRUE(m.Open(OpenRequest("a", "pleo", EMOTION_NEUTRAL)).ok());
    for (int i = 0; i < 25; ++i) {
      clock.Advance(0.01);
      ASSERT_TRUE(m.Act("a", i % 2 ? ACTION_KISSES : ACTION_IDLE, 0.1, false).ok());
    }
    cube_tracker::v1::VideoSource source;
    source.set_video_file("cube/vleo.mp4");
    source.set_realtime(true);
    cube_tracker::v1::TrackConfig config;
    config.set_cube_id("vleo");
    auto attached = m.AttachCube("a", source, config);
    ASSERT_TRUE(attached.ok()) << attached.status();
    EXPECT_TRUE(attached->cube_attached());
    EXPECT_EQ(attached->vleo(), v1::VLEO_KIND_CUBE);
    m.OnRobotCommanded("a", EMOTION_NEUTRAL, 41, "", 3.0);
    auto rows = (*store)->LoadAll();
    ASSERT_TRUE(rows.ok());
    ASSERT_EQ(rows->size(), 1u);
    EXPECT_EQ((*rows)[0].acts, 25u);
    EXPECT_EQ((*rows)[0].robot_sequence, 41u);
    EXPECT_EQ((*rows)[0].action, ACTION_IDLE);
  }
  auto store = SqliteSessionStore::Open(dir.path);
  ASSERT_TRUE(store.ok());
  SessionManager m(Options(), &clock, nullptr, store->get());
  auto cubes = m.Restore();
  ASSERT_TRUE(cubes.ok()) << cubes.status();
  ASSERT_EQ(cubes->size(), 1u);
  EXPECT_EQ((*cubes)[0].session_id, "a");
  EXPECT_EQ((*cubes)[0].source.video_file(), "cube/vleo.mp4");
  EXPECT_TRUE((*cubes)[0].source.realtime());
  EXPECT_EQ((*cubes)[0].config.cube_id(), "vleo");
  EXPECT_TRUE(m.Get("a")->cube_attached());
  // A detach (e.g. the video ended) is stored, with its reason told.
  std::vector<v1::SessionEvent> events;
  ASSERT_TRUE(m.Subscribe("a", [&](const v1::SessionEvent& e) { events.push_back(e); }).ok());
  ASSERT_TRUE(m.DetachCube("a", "source ended").ok());
  ASSERT_FALSE(events.empty());
  EXPECT_FALSE(events.back().cube_status_changed().attached());
  EXPECT_EQ(events.back().cube_status_changed().reason(), "source ended");
  EXPECT_TRUE((*store)->LoadAll()->at(0).cube_source.empty());
}

TEST(DurableSessions, AStoreErrorFailsTheCallAndChangesNothing) {
  FakeClock clock;
  FlakyStore store;
  std::vector<v1::SessionEvent> events;
  SessionManager m(Options(), &clock, nullptr, &store);
  ASSERT_TRUE(m.Open(OpenRequest("a", "pleo", EMOTION_ANGRY)).ok());
  ASSERT_TRUE(m.Subscribe("", [&](const v1::SessionEvent& e) { events.push_back(e); }).ok());
  events.clear();
  store.fail = true;
  auto opened = m.Open(OpenRequest("b", "pleo", EMOTION_ANGRY));
  EXPECT_EQ(opened.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_TRUE(absl::StartsWith(opened.status().message(), "store_dir:"));
  EXPECT_EQ(m.size(), 1u);
  clock.Advance(1);
  EXPECT_FALSE(m.Act("a", ACTION_KISSES, 1, false).ok());
  EXPECT_FALSE(m.Close("a", true, "client").ok());
  cube_tracker::v1::VideoSource source;
  source.set_video_file("v.mp4");
  EXPECT_FALSE(m.AttachCube("a", source, {}).ok());
  auto a = m.Get("a");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->action(), ACTION_IDLE);
  EXPECT_EQ(a->valence(), -1.0);
  EXPECT_FALSE(a->cube_attached());
  EXPECT_TRUE(events.empty());  // nobody was told about a change
  EXPECT_EQ(store.rows.at("a").acts, 0u);
  store.fail = false;
  ASSERT_TRUE(m.Act("a", ACTION_KISSES, 1, false).ok());
  EXPECT_EQ(store.rows.at("a").acts, 1u);
  ASSERT_TRUE(m.Close("a", false, "client").ok());
  EXPECT_TRUE(store.rows.empty());
}

TEST(DurableSessions, AClosedSessionReleasesItsRobotToTheNextSession) {
  FakeClock clock;
  std::vector<RobotCommand> commands;
  SessionManager m(Options(), &clock, [&](const RobotCommand& c) { commands.push_back(c); });
  ASSERT_TRUE(m.Open(OpenRequest("old", "pleo", EMOTION_ANGRY)).ok());
  ASSERT_TRUE(m.Open(OpenRequest("new", "pleo", EMOTION_HAPPY)).ok());
  ASSERT_TRUE(m.Open(OpenRequest("alone", "pleo-2", EMOTION_HAPPY)).ok());
  commands.clear();
  ASSERT_TRUE(m.Close("new", false, "client").ok());
  ASSERT_EQ(commands.size(), 2u);
  EXPECT_TRUE(commands[0].release);
  EXPECT_EQ(commands[0].session_id, "new");
  EXPECT_EQ(commands[0].emotion, EMOTION_UNSPECIFIED);  // nothing to send
  EXPECT_FALSE(commands[1].release);                    // the older session takes over
  EXPECT_EQ(commands[1].session_id, "old");
  EXPECT_EQ(commands[1].emotion, EMOTION_ANGRY);
  commands.clear();
  ASSERT_TRUE(m.Close("alone", true, "client").ok());
  ASSERT_EQ(commands.size(), 1u);  // neutral, once, and nobody else
  EXPECT_TRUE(commands[0].release);
  EXPECT_EQ(commands[0].emotion, EMOTION_NEUTRAL);
}

TEST(SqliteSessionStore, ACorruptOrUnusableStoreIsAnErrorNamingStoreDir) {
  ScratchDir dir;
  {
    std::ofstream(dir.path + "/sessions.db") << std::string(8192, 'x');
    auto s = SqliteSessionStore::Open(dir.path);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_TRUE(absl::StartsWith(s.status().message(), "store_dir: " + dir.path)) << s.status();
  }
  {
    std::ofstream(dir.path + "/file") << "not a directory";
    auto s = SqliteSessionStore::Open(dir.path + "/file/sessions");
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_TRUE(absl::StartsWith(s.status().message(), "store_dir: ")) << s.status();
  }
  {
    // A valid SQLite file of a newer schema.
    std::filesystem::remove(dir.path + "/sessions.db");
    ASSERT_TRUE(SqliteSessionStore::Open(dir.path).ok());
    auto s = SqliteSessionStore::Open(dir.path);
    ASSERT_TRUE(s.ok());
  }
}

}  // namespace
}  // namespace kinemo::coordinator
