// Durable sessions with real processes on loopback (pleo_sim x2,
// robot_bridge, coordinator with a store_dir): a client streams kisses and
// shouts, the coordinator is killed with SIGKILL mid-stream and restarted on
// the same store_dir. Every acknowledged Act must be in the store and in the
// restored session, the sessions must all be back (and a closed one not),
// and each Pleo must end in the emotion the model gives. Also: a graceful
// shutdown keeps the sessions, and a corrupt or unusable store is a clear
// start-up error.
#include <atomic>
#include <cmath>
#include <filesystem>
#include <map>

#include "services/coordinator/core/sqlite_session_store.h"
#include "tests/integration/coordinator/vleo_stack.h"

namespace kinemo::coordinator {
namespace {

using namespace vleo_test;
using common::v1::ACTION_KISSES;
using common::v1::ACTION_SHOUTING;
using common::v1::EMOTION_ANGRY;
using common::v1::EMOTION_HAPPY;
using common::v1::EMOTION_NEUTRAL;

// What the client saw of one session.
struct Seen {
  int acked = 0;               // Acts answered OK
  double last_intensity = 0;   // of the last acknowledged Act
  double last_valence = 0;     // in its answer
  bool in_flight = false;      // an Act sent and not answered (the kill)
  double in_flight_intensity = 0;
};

TEST(Durability, ASigkilledCoordinatorLosesNoAcknowledgedAct) {
  Stack st({"pleo-a", "pleo-b"});
  st.store_dir = st.dir.File("store");
  st.rate_per_s = 0.5;  // at the intensities below, angry -> happy in ~5 s
  ASSERT_NO_FATAL_FAILURE(st.Start());
  // A session opened and closed before: it must stay closed.
  ASSERT_TRUE(st.Open("closed", EMOTION_NEUTRAL, "pleo-b").ok());
  ASSERT_TRUE(st.Close("closed", false).ok());
  ASSERT_TRUE(st.Open("kiss", EMOTION_ANGRY, "pleo-a").ok());
  ASSERT_TRUE(st.Open("shout", EMOTION_HAPPY, "pleo-b").ok());
  ASSERT_TRUE(st.PleoShows(EMOTION_ANGRY, 10s, "pleo-a"));
  ASSERT_TRUE(st.PleoShows(EMOTION_HAPPY, 10s, "pleo-b"));

  // The client: Acts one after the other, each with its own intensity, until
  // one fails (the coordinator is gone).
  std::map<std::string, Seen> seen;
  std::atomic<int> acked_total{0};
  std::thread client([&] {
    for (int k = 0;; ++k) {
      const bool kiss = k % 2 == 0;
      const std::string id = kiss ? "kiss" : "shout";
      const double intensity = 0.2 + 1e-5 * k;  // unique per Act
      Seen& s = seen[id];
      s.in_flight = true;
      s.in_flight_intensity = intensity;
      v1::ActResponse resp;
      if (!st.Act(id, kiss ? ACTION_KISSES : ACTION_SHOUTING, intensity, &resp).ok()) return;
      s.in_flight = false;
      ++s.acked;
      s.last_intensity = intensity;
      s.last_valence = resp.session().valence();
      acked_total.fetch_add(1);
    }
  });
  // Mid-stream: after 400 acknowledged Acts, SIGKILL.
  const auto give_up = std::chrono::steady_clock::now() + 30s;
  while (acked_total.load() < 400 && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(5ms);
  }
  auto killed = st.coordinator->process().Stop(SIGKILL, 5s);
  client.join();
  ASSERT_TRUE(killed.ok());
  EXPECT_EQ(*killed, 128 + SIGKILL);
  ASSERT_GE(acked_total.load(), 400);
  const double killed_wall_s =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();

  // The store holds every acknowledged Act (and at most the one in flight).
  {
    auto store = SqliteSessionStore::Open(st.store_dir);
    ASSERT_TRUE(store.ok()) << store.status();
    auto rows = (*store)->LoadAll();
    ASSERT_TRUE(rows.ok()) << rows.status();
    ASSERT_EQ(rows->size(), 2u);
    for (const StoredSession& row : *rows) {
      SCOPED_TRACE(row.session_id);
      ASSERT_TRUE(seen.count(row.session_id));
      const Seen& s = seen[row.session_id];
      if (row.acts == static_cast<std::uint64_t>(s.acked)) {
        EXPECT_EQ(row.intensity, s.last_intensity);
      } else {
        // The Act in flight at the kill was committed, not answered.
        EXPECT_TRUE(s.in_flight);
        EXPECT_EQ(row.acts, static_cast<std::uint64_t>(s.acked) + 1);
        EXPECT_EQ(row.intensity, s.in_flight_intensity);
      }
    }
  }

  // Restart on the same store_dir: every session is back, as stored.
  ASSERT_NO_FATAL_FAILURE(st.StartCoordinator());
  v1::ListSessionsResponse listed;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->ListSessions(&ctx, v1::ListSessionsRequest(), &listed).ok());
  }
  ASSERT_EQ(listed.sessions_size(), 2);
  EXPECT_EQ(listed.sessions(0).session_id(), "kiss");
  EXPECT_EQ(listed.sessions(1).session_id(), "shout");
  const double restored_wall_s =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  for (const v1::Session& got : listed.sessions()) {
    SCOPED_TRACE(got.session_id());
    const Seen& s = seen[got.session_id()];
    const bool kiss = got.session_id() == "kiss";
    EXPECT_EQ(got.action(), kiss ? ACTION_KISSES : ACTION_SHOUTING);
    EXPECT_TRUE(got.intensity() == s.last_intensity ||
                (s.in_flight && got.intensity() == s.in_flight_intensity));
    // The model ran on over the downtime, at most at full rate.
    const double moved = got.valence() - s.last_valence;
    EXPECT_GE(kiss ? moved : -moved, 0.0);
    EXPECT_LE(std::abs(moved), st.rate_per_s * (restored_wall_s - killed_wall_s + 30.0));
  }
  // Each Pleo ends in the emotion the model gives: the sessions reach
  // happy / angry, and the robots show it.
  const auto until = std::chrono::steady_clock::now() + 30s;
  v1::Session kiss, shout;
  while (std::chrono::steady_clock::now() < until) {
    ASSERT_TRUE(st.Get("kiss", &kiss).ok());
    ASSERT_TRUE(st.Get("shout", &shout).ok());
    if (kiss.emotion() == EMOTION_HAPPY && shout.emotion() == EMOTION_ANGRY) break;
    std::this_thread::sleep_for(50ms);
  }
  ASSERT_EQ(kiss.emotion(), EMOTION_HAPPY);
  ASSERT_EQ(shout.emotion(), EMOTION_ANGRY);
  EXPECT_TRUE(st.PleoShows(EMOTION_HAPPY, 10s, "pleo-a")) << st.coordinator->process().ReadLog();
  EXPECT_TRUE(st.PleoShows(EMOTION_ANGRY, 10s, "pleo-b")) << st.coordinator->process().ReadLog();
  // The restored session follows its robot again (the bridge's status stream).
  const auto status_until = std::chrono::steady_clock::now() + 10s;
  while (std::chrono::steady_clock::now() < status_until) {
    ASSERT_TRUE(st.Get("kiss", &kiss).ok());
    if (kiss.robot_connected() && kiss.robot_emotion() == EMOTION_HAPPY) break;
    std::this_thread::sleep_for(50ms);
  }
  EXPECT_TRUE(kiss.robot_connected());
  EXPECT_EQ(kiss.robot_emotion(), EMOTION_HAPPY);
}

TEST(Durability, AGracefulShutdownKeepsTheSessions) {
  Stack st;
  st.store_dir = st.dir.File("store");
  ASSERT_NO_FATAL_FAILURE(st.Start());
  ASSERT_TRUE(st.Open("vleo", EMOTION_ANGRY).ok());
  ASSERT_TRUE(st.Act("vleo", ACTION_KISSES, 1.0).ok());
  auto code = st.coordinator->Stop();
  ASSERT_TRUE(code.ok());
  EXPECT_EQ(*code, 0);
  ASSERT_NO_FATAL_FAILURE(st.StartCoordinator());
  v1::Session s;
  ASSERT_TRUE(st.Get("vleo", &s).ok());
  EXPECT_EQ(s.action(), ACTION_KISSES);
  // Open again with the same id: it is open already.
  EXPECT_EQ(st.Open("vleo", EMOTION_NEUTRAL).error_code(), grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_TRUE(st.PleoShows(EMOTION_HAPPY, 15s));
}

TEST(Durability, ACorruptOrUnusableStoreIsAClearStartUpError) {
  kinemo::testing::TempDir dir;
  std::ofstream(dir.File("not-a-dir")) << "a file";
  const std::string corrupt = dir.File("corrupt");
  ASSERT_TRUE(std::filesystem::create_directories(corrupt));
  std::ofstream(corrupt + "/sessions.db") << std::string(4096, '\x5a');
  for (const std::string& store : {corrupt, dir.File("not-a-dir") + "/store"}) {
    SCOPED_TRACE(store);
    const std::string cfg = dir.File("coordinator.textproto");
    std::ofstream(cfg) << "store_dir: \"" << store << "\"\n";
    std::string out;
    auto code = ChildProcess::Run({kBin + "/services/coordinator/coordinator", "--config", cfg,
                                   "--host", "127.0.0.1", "--port", "0"},
                                  dir.File("coordinator.log"), 20s, &out);
    ASSERT_TRUE(code.ok()) << code.status();
    EXPECT_EQ(*code, 2) << out;
    EXPECT_NE(out.find("store_dir: " + store), std::string::npos) << out;
  }
}

}  // namespace
}  // namespace kinemo::coordinator
