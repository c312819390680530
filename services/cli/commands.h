// The `kinemo` command-line tool: one Register*Commands() per area, each in
// its own cmd_<area>.cc. A command's handler returns the process exit code
// through CliExit (0 ok, 1 runtime failure, 2 bad input or usage).
#pragma once

#include <CLI/CLI.hpp>

namespace kinemo::cli {

// Thrown by command callbacks to end the program with a given exit code after
// printing nothing more (the handler has already written its message).
struct CliExit {
  int code;
};

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
void RegisterE2eBenchCommands(CLI::App& app);
void RegisterDemoCommands(CLI::App& app);
void RegisterControllerCommands(CLI::App& app);
void RegisterGestureCommands(CLI::App& app);

}  // namespace kinemo::cli
