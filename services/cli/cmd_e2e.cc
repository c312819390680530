// kinemo bench e2e — end-to-end latencies and session capacity of the stack
// (services/coordinator/bench/e2e_bench.h).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>

#include "nlohmann/json.hpp"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/coordinator/bench/e2e_bench.h"
#include "services/robot_bridge/bench/robot_bench.h"

namespace kinemo::cli {

void RegisterE2eBenchCommands(CLI::App& app) {
  // `bench` may be shared with other areas: reuse it if it exists.
  CLI::App* bench = nullptr;
  try {
    bench = app.get_subcommand("bench");
  } catch (const CLI::OptionNotFound&) {
    bench = app.add_subcommand("bench", "Benchmarks of the whole system");
    bench->require_subcommand(1);
  }
  auto* cmd = bench->add_subcommand(
      "e2e", "Cube event -> robot register, audio chunk -> motion frame, concurrent sessions");
  struct Args {
    coordinator::E2eBenchOptions o;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--pleo-sim", a->o.pleo_sim, "pleo_sim binary (default: beside this program)");
  cmd->add_option("--actions", a->o.actions, "emotion flips measured")->capture_default_str();
  cmd->add_option("--sessions", a->o.sessions, "sessions opened at once")->capture_default_str();
  cmd->add_option("--coordinator", a->o.coordinator,
                  "a running coordinator with models, for audio -> frame (StreamAnimate)");
  cmd->add_option("--model", a->o.model_id, "inference model id (audio -> frame)");
  cmd->add_option("--controller", a->o.controller_id, "controller id (audio -> frame)");
  cmd->add_option("--speech", a->o.speech_file, "recording streamed for audio -> frame");
  cmd->add_flag("--json", a->json, "one JSON object");
  cmd->callback([a] {
    if (a->o.pleo_sim.empty()) a->o.pleo_sim = robot_bridge::FindPleoSim("/proc/self/exe");
    if (a->o.speech_file.empty()) {
      const char* shared = std::getenv("KINEMO_SHARED_DATA_DIR");
      a->o.speech_file = std::string(shared != nullptr ? shared : "tests/data") +
                         "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";
    }
    a->o.coordinator_tls = CliTlsFiles();
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
    if (r->audio_to_frame_p99_ms) {
      std::printf("audio chunk -> motion frame           p50 %7.2f ms  p99 %7.2f ms\n",
                  *r->audio_to_frame_p50_ms, *r->audio_to_frame_p99_ms);
    } else {
      std::printf("audio chunk -> motion frame           not measured: %s\n",
                  r->audio_note.c_str());
    }
    std::printf("sessions held and running             %d (opened in %.2f s)\n", r->sessions,
                r->sessions_open_s);
  });
}

}  // namespace kinemo::cli
