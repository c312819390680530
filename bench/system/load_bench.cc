#include "bench/system/load_bench.h"

#include <chrono>
#include <fstream>
#include <sstream>

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include "common/audio/decode.h"
#include "services/coordinator/client/live_client.h"

namespace kinemo::coordinator {
namespace {

// CPU seconds (utime + stime) of process `pid` (0 = this one); -1 if unreadable.
double ProcessCpuS(pid_t pid) {
  std::ifstream f(pid == 0 ? std::string("/proc/self/stat") : "/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(f, line)) return -1;
  // The command name (field 2) may hold spaces: fields restart after its ')'.
  const auto close = line.rfind(')');
  if (close == std::string::npos) return -1;
  std::istringstream rest(line.substr(close + 2));
  std::string field;
  double utime = 0, stime = 0;
  for (int i = 3; i <= 15 && rest >> field; ++i) {
    if (i == 14) utime = std::stod(field);
    if (i == 15) stime = std::stod(field);
  }
  return (utime + stime) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

// Busy CPU seconds of the whole machine (every core), from /proc/stat.
double MachineBusyS() {
  std::ifstream f("/proc/stat");
  std::string cpu;
  f >> cpu;
  double v[8] = {0};
  for (double& x : v) f >> x;
  // user nice system idle iowait irq softirq steal
  const double busy = v[0] + v[1] + v[2] + v[5] + v[6] + v[7];
  return busy / static_cast<double>(sysconf(_SC_CLK_TCK));
}

}  // namespace

Status RunLoadBench(const LoadBenchOptions& o, const std::function<void(const LoadBenchRow&)>& on_row) {
  if (o.streams.empty()) return InvalidField("streams", "give at least one count");
  for (std::size_t i = 0; i < o.streams.size(); ++i) {
    if (o.streams[i] < 1 || o.streams[i] > 4096) {
      return InvalidField(StrCat("streams[", i, "]"), o.streams[i], " is not in [1, 4096]");
    }
  }
  auto audio = audio::DecodeAudioFile(o.speech_file);
  if (!audio.ok()) return audio.status();
  KINEMO_ASSIGN_OR_RETURN(auto credentials, MakeChannelCredentials(o.coordinator_tls));
  LiveStreamOptions lo;
  lo.realtime = o.realtime;
  lo.keep_frames = false;
  lo.start_after_setup = true;
  lo.config.mutable_models()->set_inference_model_id(o.model_id);
  lo.config.mutable_models()->set_controller_id(o.controller_id);
  lo.config.set_request_id("bench-load");
  std::vector<std::pair<int, std::string>> rows;
  for (int n : o.streams) {
    if (o.side_by_side && !o.rig_id.empty()) rows.emplace_back(n, "");
    rows.emplace_back(n, o.rig_id);
  }
  for (const auto& [n, rig_id] : rows) {
    lo.config.mutable_models()->set_rig_id(rig_id);
    // A channel per row: each row starts from a fresh connection. (One HTTP/2
    // connection carries every stream, as one front end would.)
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    auto channel = grpc::CreateCustomChannel(o.coordinator, credentials, args);
    LoadBenchRow row;
    row.streams = n;
    row.rig_id = rig_id;
    row.cpu_source = o.stack_pid > 0 ? StrCat("process ", o.stack_pid) : "machine less client";
    const auto t0 = std::chrono::steady_clock::now();
    const double stack0 = o.stack_pid > 0 ? ProcessCpuS(o.stack_pid) : MachineBusyS();
    const double client0 = ProcessCpuS(0);
    auto results = RunLiveStreams(channel, audio->samples, audio->sample_rate_hz, lo, n);
    const double client1 = ProcessCpuS(0);
    const double stack1 = o.stack_pid > 0 ? ProcessCpuS(o.stack_pid) : MachineBusyS();
    row.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::vector<double> lags, setups;
    for (auto& r : results) {
      if (r.ok()) {
        ++row.admitted;
        lags.insert(lags.end(), r->motion_lag_ms.begin(), r->motion_lag_ms.end());
        row.max_gap_ms = std::max(row.max_gap_ms, r->max_frame_gap_ms);
        row.max_chunk_late_ms = std::max(row.max_chunk_late_ms, r->max_chunk_late_ms);
        row.speech_s = r->audio_s;
        setups.push_back(r->setup_ms);
        row.setup_max_ms = std::max(row.setup_max_ms, r->setup_ms);
      } else if (r.status().code() == absl::StatusCode::kResourceExhausted) {
        ++row.refused;
      } else {
        if (row.failed++ == 0) row.first_error = r.status().ToString();
      }
    }
    // A stream that failed after it was admitted (other than by refusal)
    // still counts as admitted: it took a slot.
    row.admitted += row.failed;
    if (results.size() == 1 && row.failed == 1 && n > 1) return results[0].status();  // bad arguments
    row.lag_p50_ms = Percentile(lags, 0.5);
    row.lag_p99_ms = Percentile(lags, 0.99);
    row.setup_p50_ms = Percentile(setups, 0.5);
    const double client_s = client1 - client0;
    double stack_s = stack1 - stack0;
    if (o.stack_pid == 0) stack_s -= client_s;
    row.client_cpu = row.wall_s > 0 ? client_s / row.wall_s : 0;
    row.cpu_per_stream = row.admitted > 0 && row.wall_s > 0 ? stack_s / row.admitted / row.wall_s : 0;
    on_row(row);
  }
  return absl::OkStatus();
}

}  // namespace kinemo::coordinator
