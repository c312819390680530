// kinemo_cube: the cube commands on their own, for use before (and beside) the
// `kinemo` CLI, which registers the same commands (services/cli/cmd_cube.cc).
#include <CLI/CLI.hpp>

#include "services/cli/cmd_cube.h"

int main(int argc, char** argv) {
  CLI::App app{"kinemo cube tools"};
  app.require_subcommand(1);
  kinemo::cli::RegisterCubeCommands(app);
  CLI11_PARSE(app, argc, argv);
  return 0;
}
