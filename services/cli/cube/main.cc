// kinemo-cube: the AR cube tools. `kinemo cube ARGS...` executes
// `kinemo-cube ARGS...`. They live in their own executable because OpenCV's
// video and image codecs load ~280 shared libraries, which would add 0.3 s
// of start-up to every other `kinemo` command.
#include <string>
#include <vector>

#include "services/cli/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"kinemo: body language from speech, and a cube that drives a robot's mood", "kinemo"};
  app.require_subcommand(1);
  kinemo::cli::RegisterCubeCommands(app);
  // Parse as `kinemo cube ARGS...`, so help and errors read like the main tool.
  std::vector<char*> args = {argv[0], const_cast<char*>("cube")};
  for (int i = 1; i < argc; ++i) args.push_back(argv[i]);
  try {
    app.parse(static_cast<int>(args.size()), args.data());
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const kinemo::cli::CliExit& e) {
    return e.code;
  }
  return 0;
}
