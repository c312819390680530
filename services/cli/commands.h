// The `kinemo` command-line tool: one Register*Commands() per area, each in
// its own cmd_<area>.cc. A command's handler returns the process exit code
// through CliExit (0 ok, 1 runtime failure, 2 bad input or usage).
#pragma once

#include <CLI/CLI.hpp>

#include <initializer_list>
#include <iostream>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::cli {

// Thrown by command callbacks to end the program with a given exit code after
// printing nothing more (the handler has already written its message).
struct CliExit {
  int code;
};

// Prints "kinemo <command>: <message>" on stderr and ends the command:
// exit code 2 when the status code is one of `bad_input` (bad input or
// usage), 1 otherwise.
[[noreturn]] inline void FailCommand(std::string_view command, const Status& status,
                                     std::initializer_list<absl::StatusCode> bad_input) {
  std::cerr << "kinemo " << command << ": " << std::string(status.message()) << "\n";
  bool is_bad_input = false;
  for (absl::StatusCode code : bad_input) is_bad_input = is_bad_input || status.code() == code;
  throw CliExit{is_bad_input ? 2 : 1};
}

// "a, b,,c" -> {"a", "b", "c"}: comma-separated items, trimmed, empty ones
// dropped; lower-cased when `lower`.
inline std::vector<std::string> SplitList(const std::string& list, bool lower = false) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= list.size()) {
    size_t end = list.find(',', start);
    if (end == std::string::npos) end = list.size();
    std::string item = list.substr(start, end - start);
    while (!item.empty() && item.front() == ' ') item.erase(item.begin());
    while (!item.empty() && item.back() == ' ') item.pop_back();
    if (lower) {
      for (char& c : item) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    }
    if (!item.empty()) out.push_back(std::move(item));
    start = end + 1;
  }
  return out;
}

// An old spelling of an option, kept for one release (docs/cli.md "One
// spelling per concept"): OLD sets the same variable as NEW, is hidden from --help,
// and each use prints a deprecation note on stderr (stdout stays the
// command's output), after PROGRAM's name.
template <typename T>
CLI::Option* AddDeprecatedOption(CLI::App* cmd, const std::string& old_name, const std::string& new_name, T& variable,
                                 const std::string& program = "kinemo") {
  CLI::Option* opt = nullptr;
  if constexpr (std::is_same_v<T, bool>) {
    opt = cmd->add_flag(old_name, variable, "deprecated: use " + new_name);
  } else {
    opt = cmd->add_option(old_name, variable, "deprecated: use " + new_name);
  }
  return opt->group("")->each([old_name, new_name, program](const std::string&) {
    std::cerr << program << ": " << old_name << " is deprecated and will be removed in the next release; use "
              << new_name << "\n";
  });
}

// The subcommand NAME of APP that several areas add commands to (`bench`,
// `demo`): the one an earlier area added, else a new one that requires a
// command of its own.
inline CLI::App* SharedSubcommand(CLI::App& app, const std::string& name, const std::string& description) {
  try {
    return app.get_subcommand(name);
  } catch (const CLI::OptionNotFound&) {
  }
  CLI::App* sub = app.add_subcommand(name, description);
  sub->require_subcommand(1);
  return sub;
}

// Parses the command line and runs the chosen command; returns the exit code.
inline int RunCommandLine(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const CliExit& e) {
    return e.code;
  }
  return 0;
}

void RegisterBvhCommands(CLI::App& app);
void RegisterAudioCommands(CLI::App& app);
void RegisterProsodyCommands(CLI::App& app);
void RegisterRobotCommands(CLI::App& app);
void RegisterCrfCommands(CLI::App& app);
void RegisterCubeCommands(CLI::App& app);
void RegisterPreviewCommands(CLI::App& app);
void RegisterLocomotionCommands(CLI::App& app);
void RegisterSessionCommands(CLI::App& app);
void RegisterAnimateCommands(CLI::App& app);
// kinemo retarget (cmd_retarget.cc)
void RegisterRetargetCommands(CLI::App& app);
// kinemo studio (the web studio in front of an embedded stack)
void RegisterStudioCommands(CLI::App& app);
void RegisterE2eBenchCommands(CLI::App& app);
void RegisterToneBenchCommands(CLI::App& app);
void RegisterLongBenchCommands(CLI::App& app);
void RegisterDemoCommands(CLI::App& app);
void RegisterControllerCommands(CLI::App& app);
void RegisterGestureCommands(CLI::App& app);
void RegisterLibraryCommands(CLI::App& app);
void RegisterArtifactCommands(CLI::App& app);
void RegisterMotionCommands(CLI::App& app);
void RegisterFaceCommands(CLI::App& app);

}  // namespace kinemo::cli
