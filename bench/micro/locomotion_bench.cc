// Locomotion evaluation (thesis Tables 3.2-3.3): the default sweep (7 split
// profiles x 19 thresholds, every frame a request) on the CMU clips, on 1 and
// 2 threads, wall clock. Reads KINEMO_SHARED_DATA_DIR/motion/cmu (the five
// clips of the issue, 1,160 frames) when present, else the CMU clips of
// tests/data (fewer frames), and says which.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "services/planner/library/library.h"
#include "services/planner/locomotion/locomotion.h"

namespace kinemo::planner::locomotion {
namespace {

std::shared_ptr<const LocomotionData> CmuData() {
  static const std::shared_ptr<const LocomotionData> data = [] {
    namespace fs = std::filesystem;
    std::vector<std::string> paths;
    const fs::path shared = fs::path(KINEMO_SHARED_DATA_DIR) / "motion" / "cmu";
    std::error_code ec;
    if (fs::is_directory(shared, ec)) {
      paths.push_back(shared.string());
    } else {
      const fs::path local = fs::path(KINEMO_TEST_DATA_DIR);
      paths = {(local / "planner_locomotion" / "cmu_007_01.bvh").string(),
               (local / "motion" / "cmu_002_03.bvh").string(), (local / "motion" / "cmu_007_12_first40.bvh").string()};
    }
    auto lib = LoadLibrary("cmu", {.paths = paths});
    if (!lib.ok()) return std::shared_ptr<const LocomotionData>();
    auto d = BuildLocomotionData(std::shared_ptr<const Library>(*std::move(lib)), {});
    if (!d.ok()) return std::shared_ptr<const LocomotionData>();
    std::fprintf(stderr, "locomotion bench: %d frames from %s\n", (*d)->num_frames,
                 fs::is_directory(shared, ec) ? shared.string().c_str() : "tests/data");
    return *d;
  }();
  return data;
}

void BM_LocomotionEvaluate(benchmark::State& state) {
  const auto data = CmuData();
  if (!data) {
    state.SkipWithError("no CMU clips");
    return;
  }
  EvaluationOptions options;
  options.threads = static_cast<int>(state.range(0));
  std::size_t rows = 0;
  for (auto _ : state) {
    auto r = Evaluate(data, options);
    if (!r.ok()) {
      state.SkipWithError("evaluation failed");
      return;
    }
    rows = r->size();
  }
  state.counters["rows"] = static_cast<double>(rows);
  state.counters["frames"] = data->num_frames;
}
BENCHMARK(BM_LocomotionEvaluate)->Arg(1)->Arg(2)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime()
    ->MeasureProcessCPUTime();

}  // namespace
}  // namespace kinemo::planner::locomotion
