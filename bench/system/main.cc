// kinemo-bench: the system benchmarks — `kinemo bench e2e|load|chaos|tones|long`.
// `kinemo bench ARGS...` executes `kinemo-bench bench ARGS...` from beside
// itself: README command 1 builds only what its demo runs, and these
// benchmarks (the whole stack under load, faults and cube scenarios) are
// a minute of compiling it does not need. `bash deploy/build.sh` builds it.
#include "services/cli/channel.h"
#include "services/cli/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"kinemo: body language from speech, and a cube that drives a robot's mood", "kinemo"};
  app.require_subcommand(1);
  kinemo::cli::RegisterE2eBenchCommands(app);
  kinemo::cli::RegisterToneBenchCommands(app);
  kinemo::cli::RegisterLongBenchCommands(app);
  kinemo::cli::AddTlsOptions(app);
  return kinemo::cli::RunCommandLine(app, argc, argv);
}
