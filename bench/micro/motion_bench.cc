// kinemo_motion benchmarks: BVH parse (MB/s) on the 100-joint CMU iClone
// files, BVH write (MB/s), forward kinematics (frames/s).
//
// Reads KINEMO_SHARED_DATA_DIR/motion/cmu/*.bvh when present (../shared/data),
// else falls back to the copies in tests/data/motion and says so.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/motion/resample.h"

namespace kinemo::motion {
namespace {

struct BenchFile {
  std::string path;
  std::string text;
};

const std::vector<BenchFile>& CmuFiles() {
  static const std::vector<BenchFile>* const files = [] {
    auto* out = new std::vector<BenchFile>;
    namespace fs = std::filesystem;
    std::vector<fs::path> paths;
    const fs::path shared = fs::path(KINEMO_SHARED_DATA_DIR) / "motion" / "cmu";
    std::error_code ec;
    if (fs::is_directory(shared, ec)) {
      for (const auto& e : fs::directory_iterator(shared, ec)) {
        if (e.path().extension() == ".bvh") paths.push_back(e.path());
      }
    }
    if (paths.empty()) {
      std::fprintf(stderr, "motion_bench: %s not found; using tests/data/motion copies\n",
                   shared.string().c_str());
      const fs::path local = fs::path(KINEMO_TEST_DATA_DIR) / "motion";
      paths = {local / "cmu_002_03.bvh", local / "cmu_007_12_first40.bvh"};
    }
    std::sort(paths.begin(), paths.end());
    for (const fs::path& p : paths) {
      std::ifstream f(p, std::ios::binary);
      std::ostringstream ss;
      ss << f.rdbuf();
      out->push_back({p.string(), ss.str()});
    }
    return out;
  }();
  return *files;
}

void BM_BvhParseCmu100(benchmark::State& state) {
  const auto& files = CmuFiles();
  int64_t bytes = 0;
  for (auto _ : state) {
    for (const BenchFile& f : files) {
      StatusOr<Clip> clip = ParseBvh(f.text, f.path);
      if (!clip.ok()) {
        state.SkipWithError(std::string(clip.status().message()).c_str());
        return;
      }
      benchmark::DoNotOptimize(clip->frames.data());
      bytes += static_cast<int64_t>(f.text.size());
    }
  }
  state.SetBytesProcessed(bytes);
  state.SetLabel(std::to_string(files.size()) + " CMU iClone files");
}
BENCHMARK(BM_BvhParseCmu100)->Unit(benchmark::kMillisecond);

std::vector<Clip> LoadClips() {
  std::vector<Clip> clips;
  for (const BenchFile& f : CmuFiles()) {
    StatusOr<Clip> clip = ParseBvh(f.text, f.path);
    if (clip.ok()) clips.push_back(*std::move(clip));
  }
  return clips;
}

void BM_BvhWriteCmu100(benchmark::State& state) {
  const std::vector<Clip> clips = LoadClips();
  BvhWriteOptions options;
  options.significant_digits = static_cast<int>(state.range(0));
  int64_t bytes = 0;
  for (auto _ : state) {
    for (const Clip& clip : clips) {
      StatusOr<std::string> text = WriteBvh(clip, options);
      benchmark::DoNotOptimize(text->data());
      bytes += static_cast<int64_t>(text->size());
    }
  }
  state.SetBytesProcessed(bytes);
  state.SetLabel(options.significant_digits == 0 ? "shortest exact" : "9 significant digits");
}
BENCHMARK(BM_BvhWriteCmu100)->Arg(0)->Arg(9)->Unit(benchmark::kMillisecond);

void BM_ForwardKinematicsCmu100(benchmark::State& state) {
  const std::vector<Clip> clips = LoadClips();
  if (clips.empty()) {
    state.SkipWithError("no clips");
    return;
  }
  const Clip& clip = clips.front();
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(clip.skeleton.num_joints()));
  std::vector<Eigen::Matrix3d> rot(static_cast<size_t>(clip.skeleton.num_joints()));
  int64_t frames = 0;
  for (auto _ : state) {
    for (int f = 0; f < clip.num_frames(); ++f) {
      const Status s = ComputeWorldPose(clip.skeleton, clip.frame(f), pos, rot);
      benchmark::DoNotOptimize(s.ok());
      benchmark::DoNotOptimize(pos.data());
    }
    frames += clip.num_frames();
  }
  state.SetItemsProcessed(frames);
  state.SetLabel("frames/s, " + std::to_string(clip.skeleton.num_joints()) + " joints");
}
BENCHMARK(BM_ForwardKinematicsCmu100);

void BM_Resample60To30Cmu100(benchmark::State& state) {
  const std::vector<Clip> clips = LoadClips();
  int64_t frames = 0;
  for (auto _ : state) {
    for (const Clip& clip : clips) {
      StatusOr<Clip> out = Resample(clip, 30.0);
      benchmark::DoNotOptimize(out->frames.data());
      frames += out->num_frames();
    }
  }
  state.SetItemsProcessed(frames);
  state.SetLabel("output frames/s");
}
BENCHMARK(BM_Resample60To30Cmu100)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace kinemo::motion
