// kinemo: the command-line tool. See `kinemo --help` and README.md.
#include <iostream>

#include "services/cli/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"kinemo: body language from speech, and a cube that drives a robot's mood", "kinemo"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("kinemo 0.1.0"));
  kinemo::cli::RegisterBvhCommands(app);
  kinemo::cli::RegisterAudioCommands(app);
  kinemo::cli::RegisterProsodyCommands(app);
  kinemo::cli::RegisterRobotCommands(app);
  kinemo::cli::RegisterCrfCommands(app);
  kinemo::cli::RegisterCubeCommands(app);
  kinemo::cli::RegisterGestureCommands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const kinemo::cli::CliExit& e) {
    return e.code;
  }
  return 0;
}
