// kinemo demo vleo [--json] — the Vleo -> Pleo scenario from a rendered cube
// video against pleo_sim (services/coordinator/demo/vleo_demo.h); one line
// per Pleo state change.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>

#include "common/logging/log.h"
#include "nlohmann/json.hpp"
#include "services/cli/commands.h"
#include "services/coordinator/demo/vleo_demo.h"
#include "bench/robot/robot_bench.h"

namespace kinemo::cli {

namespace {

const char* Word(int v, bool action) {
  if (action) {
    switch (v) {
      case common::v1::ACTION_IDLE: return "idle";
      case common::v1::ACTION_KISSES: return "kisses";
      case common::v1::ACTION_SHOUTING: return "shouting";
      default: return "unspecified";
    }
  }
  switch (v) {
    case common::v1::EMOTION_NEUTRAL: return "neutral";
    case common::v1::EMOTION_HAPPY: return "happy";
    case common::v1::EMOTION_ANGRY: return "angry";
    default: return "unspecified";
  }
}

}  // namespace

void RegisterDemoCommands(CLI::App& app) {
  CLI::App* demo = SharedSubcommand(app, "demo", "End-to-end demonstrations");
  auto* cmd = demo->add_subcommand(
      "vleo", "A scripted cube video drives a session; Pleo (pleo_sim) follows its emotion");
  struct Args {
    coordinator::VleoDemoOptions o;
    std::string initial = "angry";
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  a->o.cube_model = "tests/data/cube/vleo.cube";
  a->o.script = "tests/data/cube/vleo_scenario.json";
  cmd->add_option("--cube", a->o.cube_model, "cube model")->capture_default_str();
  cmd->add_option("--script", a->o.script, "cube render script")->capture_default_str();
  cmd->add_option("-o,--out", a->o.work_dir, "keep the rendered video here (default: a temp dir)");
  cmd->add_option("--pleo-sim", a->o.pleo_sim, "pleo_sim binary (default: beside this program)");
  cmd->add_option("--rate", a->o.rate_per_s, "emotion model rate per second")->capture_default_str();
  cmd->add_option("--initial", a->initial, "Pleo's initial emotion")->capture_default_str();
  cmd->add_flag("--json", a->json, "one JSON line per Pleo state change");
  cmd->callback([a] {
    // The services run in this process: only their warnings and errors are
    // worth a line beside the scenario's own.
    log::Configure(log::Level::kWarn, log::Format::kText, "kinemo");
    if (a->o.pleo_sim.empty()) a->o.pleo_sim = robot_bridge::FindPleoSim("/proc/self/exe");
    if (a->initial == "happy") a->o.initial = common::v1::EMOTION_HAPPY;
    else if (a->initial == "neutral") a->o.initial = common::v1::EMOTION_NEUTRAL;
    else if (a->initial == "angry") a->o.initial = common::v1::EMOTION_ANGRY;
    else {
      std::cerr << "kinemo demo vleo: --initial: '" << a->initial << "' is not neutral, happy or angry\n";
      throw CliExit{2};
    }
    const bool json = a->json;
    // Text: a cube action when it starts, then its intensity each time it
    // passes a quarter (0.25, 0.5, 0.75, 1), not every step of a ramp.
    auto last_action = std::make_shared<int>(-1);
    auto last_quarter = std::make_shared<int>(0);
    auto r = coordinator::RunVleoDemo(a->o, [json, last_action, last_quarter](const coordinator::v1::SessionEvent& e) {
      if (e.has_emotion_changed()) {
        const auto& c = e.emotion_changed();
        if (json) {
          nlohmann::json j = {{"time_s", e.session_time_s()},
                              {"action", Word(c.action(), true)},
                              {"intensity", c.intensity()},
                              {"emotion", Word(c.to_emotion(), false)}};
          std::printf("%s\n", j.dump().c_str());
        } else {
          std::printf("%7.2f s  %-8s %+.2f  Pleo %s -> %s\n", e.session_time_s(),
                      Word(c.action(), true), c.intensity(), Word(c.from_emotion(), false),
                      Word(c.to_emotion(), false));
        }
        std::fflush(stdout);
      } else if (!json && e.has_action_changed()) {
        const auto& c = e.action_changed();
        const int quarter = static_cast<int>(std::floor(std::abs(c.intensity()) * 4 + 1e-9));
        if (c.action() != *last_action || quarter != *last_quarter) {
          std::printf("%7.2f s  cube: %s %+.2f\n", e.session_time_s(), Word(c.action(), true), c.intensity());
          *last_action = c.action();
          *last_quarter = quarter;
        }
      }
    });
    if (!r.ok()) {
      std::cerr << "kinemo demo vleo: " << r.status().message() << "\n";
      throw CliExit{1};
    }
    std::fprintf(stderr, "final: model %s, pleo_sim shows %s (video %s)\n",
                 Word(r->final_emotion, false), Word(r->robot_shows, false), r->video.c_str());
    if (r->final_emotion != r->robot_shows) throw CliExit{1};
  });
}

}  // namespace kinemo::cli
