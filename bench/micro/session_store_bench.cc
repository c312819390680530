// What durable sessions cost per Act: SessionManager::Act in memory only, and
// with the SQLite session store (one WAL transaction per Act, committed
// before the call returns), on a temporary directory of this machine's disk.
// Eight sessions take turns, the intensity changing every call (each Act is a
// change to store).
#include <benchmark/benchmark.h>
#include <stdlib.h>

#include <filesystem>
#include <memory>
#include <string>

#include "services/coordinator/core/session_manager.h"
#include "services/coordinator/core/sqlite_session_store.h"

namespace kinemo::coordinator {
namespace {

void BM_SessionAct(benchmark::State& state) {
  const bool durable = state.range(0) != 0;
  std::string dir;
  std::unique_ptr<SqliteSessionStore> store;
  if (durable) {
    dir = (std::filesystem::temp_directory_path() / "kinemo-session-bench-XXXXXX").string();
    if (::mkdtemp(dir.data()) == nullptr) {
      state.SkipWithError("mkdtemp failed");
      return;
    }
    auto opened = SqliteSessionStore::Open(dir);
    if (!opened.ok()) {
      state.SkipWithError(std::string(opened.status().message()).c_str());
      return;
    }
    store = std::move(*opened);
  }
  SessionManagerOptions options;
  options.emotion = *ResolveEmotionParams(v1::EmotionModelOptions());
  SessionManager manager(options, SystemClock::Get(), nullptr, store.get());
  constexpr int kSessions = 8;
  const std::string ids[kSessions] = {"s0", "s1", "s2", "s3", "s4", "s5", "s6", "s7"};
  for (const std::string& id : ids) {
    v1::OpenSessionRequest r;
    r.set_session_id(id);
    r.set_robot_id("pleo");
    if (!manager.Open(r).ok()) {
      state.SkipWithError("Open failed");
      return;
    }
  }
  std::int64_t k = 0;
  for (auto _ : state) {
    auto s = manager.Act(ids[k % kSessions], common::v1::ACTION_KISSES,
                         (k % 1000) / 1000.0, false);
    if (!s.ok()) {
      state.SkipWithError("Act failed");
      break;
    }
    ++k;
  }
  state.SetLabel(durable ? "sqlite store (WAL, synchronous=NORMAL)" : "memory only");
  if (!dir.empty()) {
    store.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
}
BENCHMARK(BM_SessionAct)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace kinemo::coordinator
