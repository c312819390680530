// `kinemo bench chaos`: the process stack (pleo_sim x2, robot_bridge,
// prosody x2, inference, planner x2, cube_tracker, coordinator with a
// session store; round_robin over the replicas) under a steady load, while
// faults are injected at random times:
//   - kill:   SIGKILL one service process (any replica, the coordinator
//             included), restarted at once on its port;
//   - freeze: SIGSTOP one for 2-5 s, then SIGCONT;
//   - robot:  the robot link drops (SIGKILL of a pleo_sim; its Modbus port
//             comes back 2 s later).
// The load: live StreamAnimate streams at real-time pace (the bundled
// speech, one after the other per worker), Vleo sessions Acting (each Act
// with its own intensity, counted when acknowledged), a cube session with a
// rendered cube video attached (re-attached whenever its video ends), and
// malformed requests (an out-of-range intensity, a NaN) that must be
// refused naming the field. After each fault the bench waits until the stack
// serves again (every process healthy, every robot connected, an Act
// acknowledged), then a random pause, then the next fault. The loop is
// bounded by time and count and stops itself; then the coordinator is
// stopped and its store is read: every acknowledged Act must be in it
// (acts_lost) and every session open (sessions_lost).
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "common/status/status.h"

namespace kinemo::coordinator {

struct ChaosBenchOptions {
  double minutes = 10;
  // At most this many faults (0 = as many as fit in the time).
  int max_faults = 0;
  // Pause between the recovery of one fault and the next, uniform in
  // [gap_min_s, gap_max_s].
  double gap_min_s = 6, gap_max_s = 14;
  std::uint64_t seed = 1;
  int streams = 3;       // concurrent live streams
  int act_sessions = 4;  // Vleo sessions calling Act
  double act_every_s = 0.05;
  // A fault not recovered within this is counted as not recovered.
  double recovery_timeout_s = 60;
  // The build's binaries (bin_dir/services/<svc>/<svc>), the seed store
  // (bin_dir/share/kinemo/store), the kinemo tool (renders the cube video).
  std::string bin_dir;
  std::string kinemo;
  // tests/data (speech, planner libraries, the cube model and script).
  std::string data_dir;
  std::string speech_file;
  // Where the stack keeps its files; "" = a temporary folder (removed).
  std::string work_dir;
  // Progress lines (one per fault) go here when set.
  std::function<void(const std::string&)> progress;
};

struct ChaosFaultKindStats {
  int count = 0;
  int not_recovered = 0;
  std::vector<double> recovery_s;
  double recovery_s_p50 = 0, recovery_s_p95 = 0, recovery_s_max = 0;
  int streams_failed = 0;  // streams that ended with an error status during its windows
};

struct ChaosBenchResult {
  double wall_s = 0;
  int faults = 0;
  std::map<std::string, ChaosFaultKindStats> by_kind;  // "kill", "freeze", "robot"
  std::map<std::string, int> faults_by_target;
  std::uint64_t acts_acknowledged = 0, acts_lost = 0;
  // Acts that failed (their outcome unknown to the client: some were
  // committed before the coordinator died), and Acts stored beyond the
  // acknowledged + unknown ones (would be duplicates: must be 0).
  std::uint64_t acts_failed = 0, acts_extra = 0;
  std::map<std::string, int> acts_failed_by_code;
  int sessions_opened = 0, sessions_lost = 0;
  int streams_ok = 0, streams_failed_with_status = 0, streams_hung = 0;
  std::map<std::string, int> streams_failed_by_code;
  std::map<std::string, std::string> streams_first_error;  // by code: the first message
  int cube_attaches = 0, cube_attach_failures = 0;
  std::string cube_first_error;
  int malformed_sent = 0, malformed_refused = 0, malformed_unexpected = 0;
  std::string malformed_first_unexpected;
  double recovery_s_p50 = 0, recovery_s_p95 = 0, recovery_s_max = 0;
  double lag_p50_ms_outside_faults = 0, lag_p99_ms_outside_faults = 0, lag_p99_ms_all = 0;
  std::uint64_t lag_samples_outside = 0, lag_samples_all = 0;
  double fault_window_share = 0;  // of the run's time
};

StatusOr<ChaosBenchResult> RunChaosBench(const ChaosBenchOptions& options);

}  // namespace kinemo::coordinator
