// The Google Benchmark suite (bench/micro/*_bench.cc) inside kinemo-bench:
// `kinemo-bench micro [--benchmark_filter=REGEX ...]`, or through the CLI
// `kinemo bench micro ...`. Compiled into kinemo-bench when
// KINEMO_BUILD_BENCHMARKS is on (KINEMO_BENCH_MICRO defined).
#pragma once

namespace kinemo::bench {

// Runs the benchmarks Google Benchmark's flags select (argv[0] is the
// program, the rest its --benchmark_* flags): 0, or 1 on an unknown argument.
int RunMicroBenchmarks(int argc, char** argv);

}  // namespace kinemo::bench
