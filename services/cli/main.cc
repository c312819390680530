// kinemo: the command-line tool. See `kinemo --help` and README.md.
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "services/cli/channel.h"
#include "services/cli/commands.h"

namespace {

// `kinemo cube|demo ...` run the kinemo-vision executable installed beside
// this one (it links OpenCV's codecs, which this binary avoids for a fast start).
bool IsVisionCommand(const std::string& command) { return command == "cube" || command == "demo"; }

int ExecVision(int argc, char** argv) {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::string vision = (ec ? std::filesystem::path(argv[0]) : self).parent_path() / "kinemo-vision";
  std::vector<char*> args = {const_cast<char*>(vision.c_str())};
  for (int i = 1; i < argc; ++i) args.push_back(argv[i]);
  args.push_back(nullptr);
  execv(vision.c_str(), args.data());
  std::cerr << "kinemo " << argv[1] << ": cannot run " << vision << ": " << std::strerror(errno) << "\n";
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && IsVisionCommand(argv[1])) return ExecVision(argc, argv);
  CLI::App app{"kinemo: body language from speech, and a cube that drives a robot's mood", "kinemo"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("kinemo 0.1.0"));
  kinemo::cli::RegisterBvhCommands(app);
  kinemo::cli::RegisterAudioCommands(app);
  kinemo::cli::RegisterProsodyCommands(app);
  kinemo::cli::RegisterRobotCommands(app);
  kinemo::cli::RegisterCrfCommands(app);
  kinemo::cli::RegisterPreviewCommands(app);
  // Listed for --help; handled by ExecVision before parsing.
  app.add_subcommand("cube", "the AvatAR marker cube: net, render, track, board, calibrate, push, ls, rm (kinemo-vision)");
  app.add_subcommand("demo", "end-to-end demonstrations: vleo (kinemo-vision)");
  kinemo::cli::RegisterLocomotionCommands(app);
  kinemo::cli::RegisterSessionCommands(app);
  kinemo::cli::RegisterAnimateCommands(app);
  kinemo::cli::RegisterRetargetCommands(app);
  kinemo::cli::RegisterStudioCommands(app);
  kinemo::cli::RegisterE2eBenchCommands(app);
  kinemo::cli::RegisterToneBenchCommands(app);
  kinemo::cli::RegisterControllerCommands(app);
  kinemo::cli::RegisterGestureCommands(app);
  kinemo::cli::RegisterLibraryCommands(app);
  kinemo::cli::RegisterArtifactCommands(app);
  kinemo::cli::RegisterMotionCommands(app);
  kinemo::cli::AddTlsOptions(app);  // --ca --cert --key, after any command
  return kinemo::cli::RunCommandLine(app, argc, argv);
}
