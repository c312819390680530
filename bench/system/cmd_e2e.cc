// kinemo bench e2e — end-to-end latencies and session capacity of the stack
// (bench/system/e2e_bench.h). The live figures stream a
// recording at real-time pace through StreamAnimate: against --coordinator,
// or an embedded kinemo_allinone started as `kinemo animate` does.
// kinemo bench load — N concurrent live streams per row
// (bench/system/load_bench.h), against the same stacks.
// kinemo bench chaos — the process stack with replicas under load while
// services are killed, frozen and the robot link drops
// (bench/system/chaos_bench.h).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <cstdlib>
#include <iostream>

#include "nlohmann/json.hpp"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/embedded_stack.h"
#include "bench/system/chaos_bench.h"
#include "bench/system/e2e_bench.h"
#include "bench/system/load_bench.h"
#include "bench/robot/robot_bench.h"

namespace kinemo::cli {
namespace {
namespace cmd_e2e {  // this file's own helpers (the unity build puts files together)

// The bundled LibriVox clip (7.1 s) the live figures stream by default.
std::string BundledSpeech() {
  return std::string(KINEMO_CLI_TEST_DATA_DIR) + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";
}

void RegisterLoadBench(CLI::App* bench) {
  auto* cmd = bench->add_subcommand(
      "load", "N concurrent live StreamAnimate streams: admitted, motion lag, CPU per stream");
  struct Args {
    coordinator::LoadBenchOptions o;
    std::string allinone_config;
    std::uint32_t max_streams = 0;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  a->o.model_id = a->o.controller_id = "bundled";
  a->o.streams = {1, 8, 32, 64};
  cmd->add_option("--streams", a->o.streams, "stream counts, one row each (e.g. 1,8,32,64)")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_flag("--realtime", a->o.realtime,
                "chunks at real-time pace (else each stream sends as fast as it is taken)");
  cmd->add_option("--coordinator", a->o.coordinator,
                  "a running coordinator with models; default: an embedded kinemo_allinone");
  cmd->add_option("--allinone-config", a->allinone_config,
                  "options file of the embedded kinemo_allinone (as kinemo animate --allinone-config)");
  cmd->add_option("--max-streams", a->max_streams,
                  "animate.max_concurrent_streams of the embedded kinemo_allinone (default options only; "
                  "0 = the stack's default, 48 per core)")
      ->capture_default_str();
  cmd->add_option("--model-id", a->o.model_id, "inference model id")->capture_default_str();
  cmd->add_option("--controller-id", a->o.controller_id, "controller id")->capture_default_str();
  cmd->add_option("--rig-id", a->o.rig_id, "frames on this stored rig (models.rig_id; kinemo rig push)");
  cmd->add_flag("--side-by-side", a->o.side_by_side,
                "with --rig-id: each count twice, without and with the rig (the cost of retargeting)");
  AddDeprecatedOption(cmd, "--model", "--model-id", a->o.model_id);
  AddDeprecatedOption(cmd, "--controller", "--controller-id", a->o.controller_id);
  cmd->add_option("--speech", a->o.speech_file,
                  "recording every stream sends (default: the bundled LibriVox clip, tests/data/speech)");
  cmd->add_flag("--json", a->json, "one JSON object per row");
  cmd->callback([a] {
    if (a->o.speech_file.empty()) {
      a->o.speech_file = BundledSpeech();
    }
    EmbeddedStack embedded;
    if (a->o.coordinator.empty()) {
      a->o.coordinator = embedded.Start("bench load", a->allinone_config, 60.0, a->max_streams);
      if (a->o.coordinator.empty()) throw CliExit{1};
      a->o.stack_pid = embedded.pid();
    } else {
      a->o.coordinator_tls = CliTlsFiles();
    }
    if (!a->json) {
      std::printf("%7s %12s %8s %8s %11s %11s %10s %12s %14s %10s  (%s)\n", "streams", "rig", "admitted", "refused",
                  "lag_p50_ms", "lag_p99_ms", "max_gap_ms", "setup_max_ms", "cpu_per_stream", "client_cpu",
                  a->o.realtime ? "real time" : "as fast as taken");
    }
    const Status s = coordinator::RunLoadBench(a->o, [&](const coordinator::LoadBenchRow& r) {
      if (a->json) {
        nlohmann::json j = {{"streams", r.streams},       {"admitted", r.admitted},
                            {"lag_p50_ms", r.lag_p50_ms}, {"lag_p99_ms", r.lag_p99_ms},
                            {"cpu_per_stream", r.cpu_per_stream}, {"refused", r.refused},
                            {"failed", r.failed},         {"max_gap_ms", r.max_gap_ms},
                            {"max_chunk_late_ms", r.max_chunk_late_ms}, {"client_cpu", r.client_cpu},
                            {"setup_p50_ms", r.setup_p50_ms}, {"setup_max_ms", r.setup_max_ms},
                            {"speech_s", r.speech_s},     {"wall_s", r.wall_s},
                            {"realtime", a->o.realtime},  {"cpu_source", r.cpu_source},
                            {"rig_id", r.rig_id}};
        if (!r.first_error.empty()) j["first_error"] = r.first_error;
        std::printf("%s\n", j.dump().c_str());
      } else {
        std::printf("%7d %12s %8d %8d %11.2f %11.2f %10.2f %12.2f %14.4f %10.3f\n", r.streams,
                    r.rig_id.empty() ? "-" : r.rig_id.c_str(), r.admitted, r.refused,
                    r.lag_p50_ms, r.lag_p99_ms, r.max_gap_ms, r.setup_max_ms, r.cpu_per_stream, r.client_cpu);
        if (r.failed > 0) std::printf("        %d failed: %s\n", r.failed, r.first_error.c_str());
      }
      std::fflush(stdout);
    });
    if (!s.ok()) {
      std::cerr << "kinemo bench load: " << s.message() << "\n";
      throw CliExit{1};
    }
  });
}

void RegisterChaosBench(CLI::App* bench) {
  auto* cmd = bench->add_subcommand(
      "chaos", "The process stack with replicas under load; random kills, freezes, robot link drops");
  struct Args {
    coordinator::ChaosBenchOptions o;
    std::vector<double> gap_s = {6, 14};
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--minutes", a->o.minutes, "how long faults are injected")->capture_default_str();
  cmd->add_option("--max-faults", a->o.max_faults, "at most this many faults (0 = as many as fit)")
      ->capture_default_str();
  cmd->add_option("--gap-s", a->gap_s, "pause between a recovery and the next fault: MIN,MAX seconds")
      ->delimiter(',')
      ->expected(2);
  cmd->add_option("--seed", a->o.seed, "random seed (fault times, kinds, targets)")->capture_default_str();
  cmd->add_option("--streams", a->o.streams, "concurrent live StreamAnimate streams (real-time pace)")
      ->capture_default_str();
  cmd->add_option("--act-sessions", a->o.act_sessions, "Vleo sessions calling Act")->capture_default_str();
  cmd->add_option("--speech", a->o.speech_file,
                  "recording every stream sends (default: the bundled LibriVox clip, tests/data/speech)");
  cmd->add_option("--work-dir", a->o.work_dir, "keep the stack's files and logs here (default: a temporary folder)");
  cmd->add_flag("--json", a->json, "one JSON object");
  cmd->callback([a] {
    std::error_code ec;
    const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
    // This is kinemo-bench; the cube video comes from `kinemo cube render`.
    a->o.kinemo = FindKinemoBinary("kinemo", "cli");
    if (a->o.kinemo.empty()) {
      FailCommand("bench chaos",
                  absl::NotFoundError("kinemo: not found beside kinemo-bench, in the build tree or on PATH"), {});
    }
    a->o.bin_dir = self.parent_path().parent_path().parent_path().string();  // build/services/cli/kinemo-bench
    a->o.data_dir = KINEMO_CLI_TEST_DATA_DIR;
    if (a->o.speech_file.empty()) a->o.speech_file = BundledSpeech();
    a->o.gap_min_s = a->gap_s[0];
    a->o.gap_max_s = a->gap_s[1];
    a->o.progress = [](const std::string& line) { std::fprintf(stderr, "chaos: %s\n", line.c_str()); };
    auto r = coordinator::RunChaosBench(a->o);
    if (!r.ok()) {
      std::cerr << "kinemo bench chaos: " << r.status().message() << "\n";
      throw CliExit{1};
    }
    nlohmann::json kinds = nlohmann::json::object();
    for (const auto& [kind, k] : r->by_kind) {
      kinds[kind] = {{"count", k.count},
                     {"not_recovered", k.not_recovered},
                     {"recovery_s_p50", k.recovery_s_p50},
                     {"recovery_s_p95", k.recovery_s_p95},
                     {"recovery_s_max", k.recovery_s_max},
                     {"streams_failed", k.streams_failed}};
    }
    if (a->json) {
      nlohmann::json j = {{"faults", r->faults},
                          {"acts_acknowledged", r->acts_acknowledged},
                          {"acts_lost", r->acts_lost},
                          {"sessions_lost", r->sessions_lost},
                          {"streams_failed_with_status", r->streams_failed_with_status},
                          {"streams_hung", r->streams_hung},
                          {"recovery_s_p95", r->recovery_s_p95},
                          {"lag_p99_ms_outside_faults", r->lag_p99_ms_outside_faults},
                          {"minutes", a->o.minutes},
                          {"wall_s", r->wall_s},
                          {"faults_by_kind", kinds},
                          {"faults_by_target", r->faults_by_target},
                          {"recovery_s_p50", r->recovery_s_p50},
                          {"recovery_s_max", r->recovery_s_max},
                          {"acts_failed", r->acts_failed},
                          {"acts_failed_by_code", r->acts_failed_by_code},
                          {"acts_extra", r->acts_extra},
                          {"sessions_opened", r->sessions_opened},
                          {"streams_ok", r->streams_ok},
                          {"streams_failed_by_code", r->streams_failed_by_code},
                          {"cube_attaches", r->cube_attaches},
                          {"cube_attach_failures", r->cube_attach_failures},
                          {"malformed_sent", r->malformed_sent},
                          {"malformed_refused", r->malformed_refused},
                          {"malformed_unexpected", r->malformed_unexpected},
                          {"lag_p50_ms_outside_faults", r->lag_p50_ms_outside_faults},
                          {"lag_p99_ms_all", r->lag_p99_ms_all},
                          {"lag_samples_outside", r->lag_samples_outside},
                          {"fault_window_share", r->fault_window_share},
                          {"streams", a->o.streams},
                          {"act_sessions", a->o.act_sessions},
                          {"seed", a->o.seed}};
      if (!r->malformed_first_unexpected.empty()) j["malformed_first_unexpected"] = r->malformed_first_unexpected;
      if (!r->streams_first_error.empty()) j["streams_first_error"] = r->streams_first_error;
      if (!r->cube_first_error.empty()) j["cube_first_error"] = r->cube_first_error;
      std::printf("%s\n", j.dump().c_str());
    } else {
      std::printf("%-7s %6s %13s %14s %14s %14s %15s\n", "fault", "count", "not_recovered", "recovery_p50_s",
                  "recovery_p95_s", "recovery_max_s", "streams_failed");
      for (const auto& [kind, k] : kinds.items()) {
        std::printf("%-7s %6d %13d %14.2f %14.2f %14.2f %15d\n", kind.c_str(), k["count"].get<int>(),
                    k["not_recovered"].get<int>(), k["recovery_s_p50"].get<double>(),
                    k["recovery_s_p95"].get<double>(), k["recovery_s_max"].get<double>(),
                    k["streams_failed"].get<int>());
      }
      std::printf("faults %d in %.0f s; acts acknowledged %llu, lost %llu, failed %llu (outcome unknown), extra %llu\n",
                  r->faults, r->wall_s, static_cast<unsigned long long>(r->acts_acknowledged),
                  static_cast<unsigned long long>(r->acts_lost), static_cast<unsigned long long>(r->acts_failed),
                  static_cast<unsigned long long>(r->acts_extra));
      std::printf("sessions lost %d of %d; streams ok %d, failed with a status %d, hung %d\n", r->sessions_lost,
                  r->sessions_opened, r->streams_ok, r->streams_failed_with_status, r->streams_hung);
      std::printf("recovery p50 %.2f s, p95 %.2f s, max %.2f s; lag p50 %.1f ms, p99 %.1f ms outside faults (p99 %.1f ms all)\n",
                  r->recovery_s_p50, r->recovery_s_p95, r->recovery_s_max, r->lag_p50_ms_outside_faults,
                  r->lag_p99_ms_outside_faults, r->lag_p99_ms_all);
      std::printf("cube attaches %d (failed %d); malformed requests %d, refused naming the field %d, otherwise %d\n",
                  r->cube_attaches, r->cube_attach_failures, r->malformed_sent, r->malformed_refused,
                  r->malformed_unexpected);
    }
    std::fflush(stdout);
    if (r->streams_hung > 0) std::_Exit(1);  // their threads still run
  });
}

}  // namespace cmd_e2e
}  // namespace

void RegisterE2eBenchCommands(CLI::App& app) {
  using namespace cmd_e2e;
  CLI::App* bench = SharedSubcommand(app, "bench", "Benchmarks of the whole system");
  auto* cmd = bench->add_subcommand(
      "e2e", "Cube event -> robot register, audio chunk -> motion frame, concurrent sessions");
  struct Args {
    coordinator::E2eBenchOptions o;
    std::string allinone_config;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  a->o.model_id = a->o.controller_id = "bundled";
  cmd->add_option("--pleo-sim", a->o.pleo_sim, "pleo_sim binary (default: beside this program)");
  cmd->add_option("--actions", a->o.actions, "emotion flips measured")->capture_default_str();
  cmd->add_option("--sessions", a->o.sessions, "sessions opened at once")->capture_default_str();
  cmd->add_option("--coordinator", a->o.coordinator,
                  "a running coordinator with models for the live figures (StreamAnimate); default: an "
                  "embedded kinemo_allinone");
  cmd->add_option("--allinone-config", a->allinone_config,
                  "options file of the embedded kinemo_allinone (as kinemo animate --allinone-config)");
  cmd->add_option("--model-id", a->o.model_id, "inference model id (live figures)")->capture_default_str();
  cmd->add_option("--controller-id", a->o.controller_id, "controller id (live figures)")->capture_default_str();
  AddDeprecatedOption(cmd, "--model", "--model-id", a->o.model_id);
  AddDeprecatedOption(cmd, "--controller", "--controller-id", a->o.controller_id);
  cmd->add_option("--speech", a->o.speech_file,
                  "recording streamed at real-time pace (default: the bundled LibriVox clip, tests/data/speech)");
  cmd->add_flag("--json", a->json, "one JSON object");
  cmd->callback([a] {
    if (a->o.pleo_sim.empty()) a->o.pleo_sim = robot_bridge::FindPleoSim("/proc/self/exe");
    if (a->o.speech_file.empty()) {
      a->o.speech_file = BundledSpeech();
    }
    EmbeddedStack embedded;
    if (a->o.coordinator.empty()) {
      // The embedded stack is this process's own plaintext child.
      a->o.coordinator = embedded.Start("bench e2e", a->allinone_config, 60.0);
      if (a->o.coordinator.empty()) throw CliExit{1};
    } else {
      a->o.coordinator_tls = CliTlsFiles();
    }
    auto r = coordinator::RunE2eBench(a->o);
    if (!r.ok()) {
      std::cerr << "kinemo bench e2e: " << r.status().message() << "\n";
      throw CliExit{1};
    }
    auto opt = [](const std::optional<double>& v) {
      return v ? nlohmann::json(*v) : nlohmann::json(nullptr);
    };
    if (a->json) {
      nlohmann::json j = {{"cube_to_register_p99_ms", r->cube_to_register_p99_ms},
                          {"cube_to_register_p50_ms", r->cube_to_register_p50_ms},
                          {"bridge_round_trip_p99_ms", r->bridge_round_trip_p99_ms},
                          {"audio_to_frame_p99_ms", opt(r->audio_to_frame_p99_ms)},
                          {"audio_to_frame_p50_ms", opt(r->audio_to_frame_p50_ms)},
                          {"motion_lag_p50_ms", opt(r->motion_lag_p50_ms)},
                          {"motion_lag_p99_ms", opt(r->motion_lag_p99_ms)},
                          {"first_frame_ms", opt(r->first_frame_ms)},
                          {"max_frame_gap_ms", opt(r->max_frame_gap_ms)},
                          {"max_chunk_late_ms", opt(r->max_chunk_late_ms)},
                          {"speech_s", r->speech_s},
                          {"sessions", r->sessions},
                          {"sessions_open_s", r->sessions_open_s}};
      if (!r->audio_note.empty()) j["audio_note"] = r->audio_note;
      std::printf("%s\n", j.dump().c_str());
      return;
    }
    std::printf("cube event -> robot register written  p50 %7.2f ms  p99 %7.2f ms  (%d flips)\n",
                r->cube_to_register_p50_ms, r->cube_to_register_p99_ms, a->o.actions);
    std::printf("  of which emotion change -> bridge ack p50 %7.2f ms  p99 %7.2f ms\n",
                r->bridge_round_trip_p50_ms, r->bridge_round_trip_p99_ms);
    if (r->motion_lag_p99_ms) {
      std::printf("audio sent -> its motion received     p50 %7.2f ms  p99 %7.2f ms  (%.1f s of speech, real time)\n",
                  *r->motion_lag_p50_ms, *r->motion_lag_p99_ms, r->speech_s);
      std::printf("  first frame %.2f ms, longest gap between frame batches %.2f ms (chunks sent up to %.2f ms late)\n",
                  *r->first_frame_ms, *r->max_frame_gap_ms, *r->max_chunk_late_ms);
      std::printf("  server only: chunk -> frame batch   p50 %7.2f ms  p99 %7.2f ms\n",
                  *r->audio_to_frame_p50_ms, *r->audio_to_frame_p99_ms);
    } else {
      std::printf("audio sent -> its motion received     not measured: %s\n", r->audio_note.c_str());
    }
    std::printf("sessions held and running             %d (opened in %.2f s)\n", r->sessions,
                r->sessions_open_s);
  });
  RegisterLoadBench(bench);
  RegisterChaosBench(bench);
}

}  // namespace kinemo::cli
