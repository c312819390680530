// kinemo-bench: every benchmark of kinemo in one executable.
//  - the system benchmarks: `kinemo bench e2e|load|chaos|tones|long`;
//  - the Google Benchmark suite (bench/micro): `kinemo bench micro
//    [--benchmark_filter=REGEX ...]`, or `kinemo-bench micro ...`.
// `kinemo bench ARGS...` executes `kinemo-bench bench ARGS...` from beside
// itself: README command 1 builds only what its demo runs, and these
// benchmarks (the whole stack under load, faults and cube scenarios) are
// a minute of compiling it does not need. `bash deploy/build.sh` builds it.
#include <iostream>
#include <string_view>
#include <vector>

#include "services/cli/channel.h"
#include "services/cli/commands.h"
#ifdef KINEMO_BENCH_MICRO
#include "bench/micro/micro.h"
#endif

namespace {

constexpr const char* kMicroHelp =
    "The Google Benchmark suite (bench/micro): --benchmark_filter=REGEX, --benchmark_list_tests, ... "
    "(micro --help lists its flags)";

// `micro ARGS...` after the program (or after `bench`): Google Benchmark's
// flags, passed to it as they are.
int RunMicro(int argc, char** argv, int first_flag) {
#ifdef KINEMO_BENCH_MICRO
  std::vector<char*> args = {argv[0]};
  for (int i = first_flag; i < argc; ++i) args.push_back(argv[i]);
  args.push_back(nullptr);
  return kinemo::bench::RunMicroBenchmarks(static_cast<int>(args.size()) - 1, args.data());
#else
  (void)argc;
  (void)argv;
  (void)first_flag;
  std::cerr << "kinemo bench micro: this kinemo-bench was built without the Google Benchmark suite; "
               "configure with -DKINEMO_BUILD_BENCHMARKS=ON (Google Benchmark: libbenchmark-dev) and "
               "build the target kinemo-bench, or run `bash deploy/build.sh`\n";
  return 1;
#endif
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::string_view(argv[1]) == "micro") return RunMicro(argc, argv, 2);
  if (argc >= 3 && std::string_view(argv[1]) == "bench" && std::string_view(argv[2]) == "micro") {
    return RunMicro(argc, argv, 3);
  }
  CLI::App app{"kinemo: body language from speech, and a cube that drives a robot's mood", "kinemo"};
  app.require_subcommand(1);
  kinemo::cli::RegisterE2eBenchCommands(app);
  kinemo::cli::RegisterToneBenchCommands(app);
  kinemo::cli::RegisterLongBenchCommands(app);
  // Listed for --help; handled above, before parsing.
  kinemo::cli::SharedSubcommand(app, "bench", "Benchmarks of the whole system")->add_subcommand("micro", kMicroHelp);
  app.add_subcommand("micro", kMicroHelp);
  kinemo::cli::AddTlsOptions(app);
  return kinemo::cli::RunCommandLine(app, argc, argv);
}
