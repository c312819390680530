#include "bench/micro/micro.h"

#include <benchmark/benchmark.h>

namespace kinemo::bench {

int RunMicroBenchmarks(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

}  // namespace kinemo::bench
