// kinemo-vision: the commands that need OpenCV's video and image codecs —
// `kinemo cube ...` (the AR cube tools) and `kinemo demo ...` (the Vleo ->
// Pleo scenario from a rendered cube video). `kinemo cube|demo ARGS...`
// executes `kinemo-vision cube|demo ARGS...`: the codecs load ~280 shared
// libraries, which would add 0.3 s of start-up to every other command.
#include "services/cli/channel.h"
#include "services/cli/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"kinemo: body language from speech, and a cube that drives a robot's mood", "kinemo"};
  app.require_subcommand(1);
  kinemo::cli::RegisterCubeCommands(app);
  kinemo::cli::RegisterDemoCommands(app);
  kinemo::cli::AddTlsOptions(app);
  return kinemo::cli::RunCommandLine(app, argc, argv);
}
