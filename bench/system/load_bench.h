// The load benchmark behind `kinemo bench load`: N concurrent StreamAnimate
// streams against one coordinator, each streaming the same recording in
// 20 ms chunks (at real-time pace with `realtime`, the streams' starts
// spread over one chunk), all driven by one client thread and callback
// reactors (client/live_client.h) so that the client is not the limit. The
// N streams are opened at once, and their audio starts when all are set up
// (header received): the lag is that of N running streams; the set-up of N
// streams opened in the same instant is measured apart (setup_*_ms).
// Per N, one row (two with side_by_side: without and with models.rig_id):
//   streams   streams opened;
//   admitted  streams the coordinator took (the others were refused with
//             RESOURCE_EXHAUSTED: animate.max_concurrent_streams);
//   lag_p50_ms, lag_p99_ms  motion lag (frame received − the chunk holding
//             its time sent, client clock) over every frame of every
//             admitted stream;
//   max_gap_ms  the longest gap between frame batches of any admitted stream;
//   setup_p50_ms, setup_max_ms  config sent -> header received, per stream;
//   cpu_per_stream  CPU time of the stack ÷ admitted streams ÷ wall time, a
//             fraction of one core. The stack's CPU is its process's
//             (/proc/<pid>/stat, utime + stime) when its pid is known (the
//             embedded all-in-one); for an external coordinator it is the
//             whole machine's busy time (/proc/stat) less this process's
//             own, so it is only meaningful on a machine otherwise idle with
//             the stack on it (cpu_source says which).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <sys/types.h>

#include "common/grpc/tls_credentials.h"
#include "common/status/status.h"

namespace kinemo::coordinator {

struct LoadBenchOptions {
  std::string coordinator;  // address
  ClientTlsFiles coordinator_tls;
  std::vector<int> streams;  // one row per count, in order
  bool realtime = false;     // real-time pace (else as fast as each stream takes chunks)
  std::string speech_file;
  std::string model_id, controller_id;
  // StreamAnimateConfig.models.rig_id: the frames on a stored rig. With
  // `side_by_side`, each count runs twice, without the rig and then with it
  // (two rows): the cost of retargeting inside the stream.
  std::string rig_id;
  bool side_by_side = false;
  pid_t stack_pid = 0;       // the stack's process; 0 = external (machine CPU)
};

struct LoadBenchRow {
  int streams = 0, admitted = 0;
  int refused = 0;  // RESOURCE_EXHAUSTED
  int failed = 0;   // any other error (first_error says one)
  double lag_p50_ms = 0, lag_p99_ms = 0, max_gap_ms = 0;
  double setup_p50_ms = 0, setup_max_ms = 0;
  double max_chunk_late_ms = 0;  // the client's own lateness (its pacing thread)
  double cpu_per_stream = 0;     // of the stack (cpu_source)
  double client_cpu = 0;         // this process, fraction of a core
  double wall_s = 0, speech_s = 0;
  std::string rig_id;      // the rows' models.rig_id ("" = the library's skeleton)
  std::string cpu_source;  // "process <pid>" or "machine less client"
  std::string first_error;
};

// Runs the rows in order, calling `on_row` after each. INVALID_ARGUMENT for a
// count outside [1, 4096] (naming `streams`) or unreadable speech.
Status RunLoadBench(const LoadBenchOptions& options, const std::function<void(const LoadBenchRow&)>& on_row);

}  // namespace kinemo::coordinator
