// kinemo: the command-line tool. See `kinemo --help` and README.md.
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "common/grpc/runtime.h"
#include "services/cli/channel.h"
#include "services/cli/commands.h"

namespace {

// Commands of the executables installed beside this one:
//  - `kinemo cube|demo ...` run kinemo-vision (it links OpenCV's codecs, which
//    this binary avoids for a fast start);
//  - `kinemo bench ...` runs kinemo-bench (the system benchmarks; README
//    command 1 does not build it).
const char* CompanionOf(const std::string& command) {
  if (command == "cube" || command == "demo") return "kinemo-vision";
  if (command == "bench") return "kinemo-bench";
  return nullptr;
}

int ExecCompanion(const char* name, int argc, char** argv) {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::string companion = (ec ? std::filesystem::path(argv[0]) : self).parent_path() / name;
  std::vector<char*> args = {const_cast<char*>(companion.c_str())};
  for (int i = 1; i < argc; ++i) args.push_back(argv[i]);
  args.push_back(nullptr);
  execv(companion.c_str(), args.data());
  const int error = errno;
  std::cerr << "kinemo " << argv[1] << ": cannot run " << companion << ": " << std::strerror(error) << "\n";
  if (error == ENOENT) {
    std::cerr << "kinemo " << argv[1] << ": " << name << " is not built here (README command 1 builds only what "
              << "its demo runs); build it with `cmake --build <build dir> --target " << name
              << "` or `bash deploy/build.sh`\n";
  }
  return 1;
}

// `kinemo --help` lists the commands by what a person wants to do: animate
// speech first, then characters, the cube and the robot, the services'
// stores, and the research and benchmark tools. A command missing from here
// is listed under "Other" (tests/integration/cli/help_spellings_test.py
// fails on it).
const std::vector<std::pair<std::string, std::vector<std::string>>>& CommandGroups() {
  static const auto* groups = new std::vector<std::pair<std::string, std::vector<std::string>>>{
      {"Animate speech (start here)", {"animate", "studio"}},
      {"Characters", {"retarget", "rig", "preview", "bvh"}},
      {"Cube and robot", {"cube", "robot", "session", "demo"}},
      {"Services and stores", {"artifacts", "model", "face", "library", "controller", "graph"}},
      {"Evaluation and benchmarks", {"bench", "motion", "prosody", "audio", "gestures", "gmg", "crf", "locomotion"}},
  };
  return *groups;
}

class GroupedHelp : public CLI::Formatter {
 public:
  std::string make_subcommands(const CLI::App* app, CLI::AppFormatMode mode) const override {
    if (app->get_parent() != nullptr || mode == CLI::AppFormatMode::All) {
      return CLI::Formatter::make_subcommands(app, mode);
    }
    std::stringstream out;
    std::set<std::string> listed;
    auto section = [&](const std::string& title, const std::vector<const CLI::App*>& commands) {
      if (commands.empty()) return;
      out << "\n" << title << ":\n";
      for (const CLI::App* c : commands) out << make_subcommand(c);
    };
    for (const auto& [title, names] : CommandGroups()) {
      std::vector<const CLI::App*> commands;
      for (const std::string& name : names) {
        for (const CLI::App* c : app->get_subcommands({})) {
          if (c->get_name() == name) {
            commands.push_back(c);
            listed.insert(name);
          }
        }
      }
      section(title, commands);
    }
    std::vector<const CLI::App*> other;
    for (const CLI::App* c : app->get_subcommands({})) {
      if (!c->get_name().empty() && listed.count(c->get_name()) == 0) other.push_back(c);
    }
    section("Other", other);
    out << "\nkinemo COMMAND --help says more about each; docs/cli.md lists every command with examples.\n";
    return out.str();
  }
};

}  // namespace

int main(int argc, char** argv) {
  kinemo::UseReleaseLockChecks();
  if (argc >= 2) {
    if (const char* companion = CompanionOf(argv[1])) return ExecCompanion(companion, argc, argv);
  }
  CLI::App app{"kinemo: body language from speech, and a cube that drives a robot's mood", "kinemo"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("kinemo 0.1.0"));
  kinemo::cli::RegisterBvhCommands(app);
  kinemo::cli::RegisterAudioCommands(app);
  kinemo::cli::RegisterProsodyCommands(app);
  kinemo::cli::RegisterRobotCommands(app);
  kinemo::cli::RegisterCrfCommands(app);
  kinemo::cli::RegisterPreviewCommands(app);
  // Listed for --help; handled by ExecCompanion before parsing.
  app.add_subcommand("cube", "the AvatAR marker cube: net, render, track, board, calibrate, push, ls, rm (kinemo-vision)");
  app.add_subcommand("demo", "end-to-end demonstrations: vleo (kinemo-vision)");
  app.add_subcommand("bench", "Benchmarks of the whole system (e2e, load, chaos, tones, long) and of its parts (micro) (kinemo-bench)");
  kinemo::cli::RegisterLocomotionCommands(app);
  kinemo::cli::RegisterSessionCommands(app);
  kinemo::cli::RegisterAnimateCommands(app);
  kinemo::cli::RegisterRetargetCommands(app);
  kinemo::cli::RegisterStudioCommands(app);
  kinemo::cli::RegisterControllerCommands(app);
  kinemo::cli::RegisterGestureCommands(app);
  kinemo::cli::RegisterLibraryCommands(app);
  kinemo::cli::RegisterArtifactCommands(app);
  kinemo::cli::RegisterMotionCommands(app);
  kinemo::cli::RegisterFaceCommands(app);
  kinemo::cli::AddTlsOptions(app);  // --ca --cert --key, after any command
  app.formatter(std::make_shared<GroupedHelp>());
  return kinemo::cli::RunCommandLine(app, argc, argv);
}
