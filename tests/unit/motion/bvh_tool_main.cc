// kinemo_bvh_tool: `kinemo_bvh_tool bvh info|convert ...`, the BVH commands of
// the `kinemo` CLI in a binary of their own (used by bench/tools/bvh_compare.py
// when the full CLI is not built). Same exit codes as services/cli/main.cc.
#include "services/cli/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"kinemo BVH commands"};
  app.require_subcommand(1);
  kinemo::cli::RegisterBvhCommands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const kinemo::cli::CliExit& e) {
    return e.code;
  }
  return 0;
}
