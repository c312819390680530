// Motion compare benchmarks (common/evaluation/motion_compare.h) on the BEAT2
// takes of tests/data/paired/beat2 (SMPL-X, 55 joints, 30 fps): the near-copy
// detector on take 2_2 (1804 frames) against the bundled two-take library
// (both takes, 3710 frames), and a whole Compare (every measure, the library
// included) of take 2_2 against take 1_1. Counters: output and library frames,
// (output, library) frame pairs within tolerance.
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "common/evaluation/motion_compare.h"
#include "common/motion/bvh.h"

namespace kinemo::evaluation {
namespace {
namespace evaluation_bench {

RoleTrack TakeTrack(const std::string& name) {
  StatusOr<motion::Clip> c = motion::ReadBvhFile(std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2/" + name + ".bvh");
  if (!c.ok()) return RoleTrack{};
  StatusOr<RoleTrack> t = ExtractRoleTrack(*c, 0.01);
  return t.ok() ? *std::move(t) : RoleTrack{};
}

const std::vector<RoleTrack>& Takes() {
  static const std::vector<RoleTrack>* const takes =
      new std::vector<RoleTrack>{TakeTrack("2_scott_0_1_1"), TakeTrack("2_scott_0_2_2")};
  return *takes;
}

void BM_NearCopiesBeat2(benchmark::State& state) {
  const std::vector<RoleTrack>& takes = Takes();
  if (takes[0].num_frames() == 0 || takes[1].num_frames() == 0) {
    state.SkipWithError("tests/data/paired/beat2 missing");
    return;
  }
  NearCopyResult r;
  for (auto _ : state) {
    r = NearCopies(takes[1], takes, 0.03, 2, 60);
    benchmark::DoNotOptimize(r.longest);
  }
  state.counters["output_frames"] = takes[1].num_frames();
  state.counters["library_frames"] = takes[0].num_frames() + takes[1].num_frames();
  state.counters["pairs_within_3cm"] = r.candidate_pairs;
}
BENCHMARK(BM_NearCopiesBeat2)->Unit(benchmark::kMillisecond);

void BM_CompareBeat2WithLibrary(benchmark::State& state) {
  const std::vector<RoleTrack>& takes = Takes();
  if (takes[0].num_frames() == 0 || takes[1].num_frames() == 0) {
    state.SkipWithError("tests/data/paired/beat2 missing");
    return;
  }
  const std::vector<RoleTrack> refs = {takes[0]};
  for (auto _ : state) {
    StatusOr<Comparison> c = Compare(takes[1], refs, nullptr, takes);
    benchmark::DoNotOptimize(c.ok());
  }
}
BENCHMARK(BM_CompareBeat2WithLibrary)->Unit(benchmark::kMillisecond);

}  // namespace evaluation_bench
}  // namespace
}  // namespace kinemo::evaluation
