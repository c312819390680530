// Foot planting benchmarks (common/motion/feet.h): the per-frame cost of the
// online planter, which the live Control stream pays for every frame, on the
// 22-joint Bandai skeleton (the five gesture clips of tests/data/planner_gesture
// played one after the other, so the planter also sees the jumps between
// them) and on the 100-joint CMU iClone walk (tests/data/planner_locomotion);
// and the set-up cost of a stream (the ground level of a library, estimated
// once per FrameAssembler). Counters: frames_per_s, joints.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/bvh.h"
#include "common/motion/feet.h"

namespace kinemo::motion {
namespace {

std::vector<Clip> LoadClips(const std::vector<std::string>& paths) {
  std::vector<Clip> out;
  for (const std::string& p : paths) {
    StatusOr<Clip> c = ReadBvhFile(p);
    if (c.ok()) out.push_back(*std::move(c));
  }
  return out;
}

const std::vector<Clip>& GestureClips() {
  static const std::vector<Clip>* const clips = [] {
    namespace fs = std::filesystem;
    std::vector<std::string> paths;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(std::string(KINEMO_TEST_DATA_DIR) + "/planner_gesture", ec)) {
      if (e.path().extension() == ".bvh") paths.push_back(e.path().string());
    }
    std::sort(paths.begin(), paths.end());
    return new std::vector<Clip>(LoadClips(paths));
  }();
  return *clips;
}

const std::vector<Clip>& WalkClip() {
  static const std::vector<Clip>* const clips = new std::vector<Clip>(
      LoadClips({std::string(KINEMO_TEST_DATA_DIR) + "/planner_locomotion/cmu_007_01.bvh"}));
  return *clips;
}

// Plants every frame of `clips` in turn through one planter.
void RunPlanter(benchmark::State& state, const std::vector<Clip>& clips) {
  if (clips.empty()) {
    state.SkipWithError("no clips");
    return;
  }
  const Skeleton& sk = clips.front().skeleton;
  FootPlantParams p;
  p.contact.meters_per_unit = 0.01;
  auto planter = FootPlanter::Create(sk, MapBodyRegions(sk), clips.front().frame_time_s, p);
  if (!planter.ok()) {
    state.SkipWithError(std::string(planter.status().message()).c_str());
    return;
  }
  std::vector<double> frame(static_cast<size_t>(sk.num_channels()));
  size_t c = 0;
  int f = 0;
  for (auto _ : state) {
    const auto in = clips[c].frame(f);
    std::copy(in.begin(), in.end(), frame.begin());
    (*planter)->Apply(frame);
    benchmark::DoNotOptimize(frame.data());
    if (++f == clips[c].num_frames()) {
      f = 0;
      c = (c + 1) % clips.size();
    }
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["joints"] = sk.num_joints();
}

void BM_FootPlanterPerFrameBandai22(benchmark::State& state) { RunPlanter(state, GestureClips()); }
BENCHMARK(BM_FootPlanterPerFrameBandai22);

void BM_FootPlanterPerFrameCmu100(benchmark::State& state) { RunPlanter(state, WalkClip()); }
BENCHMARK(BM_FootPlanterPerFrameCmu100);

// The ground level of the gesture library (at most 2000 sampled frames).
void BM_EstimateGroundHeightGestureLibrary(benchmark::State& state) {
  const std::vector<Clip>& clips = GestureClips();
  if (clips.empty()) {
    state.SkipWithError("no clips");
    return;
  }
  std::vector<const Clip*> ptrs;
  for (const Clip& c : clips) ptrs.push_back(&c);
  const StatusOr<FeetRig> rig = FeetRig::Find(clips.front().skeleton, MapBodyRegions(clips.front().skeleton));
  if (!rig.ok()) {
    state.SkipWithError(std::string(rig.status().message()).c_str());
    return;
  }
  for (auto _ : state) benchmark::DoNotOptimize(EstimateGroundHeight(ptrs, *rig, 0.01));
}
BENCHMARK(BM_EstimateGroundHeightGestureLibrary)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace kinemo::motion
