// `kinemo cube ...`: the cube tracker's commands (net, render, track, board, calibrate).
#pragma once

#include <CLI/CLI.hpp>

namespace kinemo::cli {

void RegisterCubeCommands(CLI::App& app);

}  // namespace kinemo::cli
