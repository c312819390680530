// Cube tracker throughput at 640x480 on one core: detection + pose + state per
// frame, on frames rendered over real photographs (tests/data/images).
#include <map>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/core.hpp>

#include "services/cube_tracker/core/tracker.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube {
namespace {

struct Frames {
  CubeModel model;
  CameraModel camera;
  std::vector<cv::Mat> bgr;
  std::vector<double> time_s;
};

const Frames& LoadFrames(const std::string& script_name) {
  static std::map<std::string, Frames>* cache = new std::map<std::string, Frames>();
  auto it = cache->find(script_name);
  if (it != cache->end()) return it->second;
  Frames& f = (*cache)[script_name];
  const std::string data = KINEMO_TEST_DATA_DIR;
  auto model = LoadCubeModel(data + "/cube/vleo.cube");
  auto script = LoadRenderScript(data + "/cube/" + script_name + ".json");
  if (!model.ok() || !script.ok()) return f;
  f.model = *model;
  auto renderer = SequenceRenderer::Create(f.model, *script);
  if (!renderer.ok()) return f;
  f.camera = renderer->camera();
  cv::Mat frame;
  TruthFrame truth;
  // Every third frame of the sequence: 100 or so frames kept in memory.
  for (int64_t i = 0; i < renderer->frame_count(); ++i) {
    if (!renderer->Next(&frame, &truth).ok()) break;
    if (i % 3 == 0) {
      f.bgr.push_back(frame.clone());
      f.time_s.push_back(truth.time_s);
    }
  }
  return f;
}

void TrackSequence(benchmark::State& state, const std::string& script, bool roi) {
  cv::setNumThreads(1);
  const Frames& f = LoadFrames(script);
  if (f.bgr.empty()) {
    state.SkipWithError("could not render the sequence (tests/data missing?)");
    return;
  }
  TrackerOptions options;
  options.detector.roi_tracking = roi;
  auto tracker = CubeTracker::Create(f.model, f.camera, options);
  if (!tracker.ok()) {
    state.SkipWithError("tracker setup failed");
    return;
  }
  CubeState out;
  size_t i = 0;
  int64_t visible = 0;
  for (auto _ : state) {
    if (!tracker->Process(f.bgr[i], f.time_s[i], &out).ok()) {
      state.SkipWithError("frame failed");
      return;
    }
    visible += out.visible;
    if (++i == f.bgr.size()) {
      i = 0;
      tracker->Reset();
    }
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["fps"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["visible"] = static_cast<double>(visible) / static_cast<double>(state.iterations());
}

void BM_CubeTrack_RotateTwoTurns(benchmark::State& s) { TrackSequence(s, "rotate_two_turns", true); }
void BM_CubeTrack_LiftRotatePlace(benchmark::State& s) { TrackSequence(s, "lift_rotate_place", true); }
void BM_CubeTrack_MovePath(benchmark::State& s) { TrackSequence(s, "move_path", true); }
void BM_CubeTrack_MovePath_FullFrame(benchmark::State& s) { TrackSequence(s, "move_path", false); }
BENCHMARK(BM_CubeTrack_RotateTwoTurns)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CubeTrack_LiftRotatePlace)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CubeTrack_MovePath)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CubeTrack_MovePath_FullFrame)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace kinemo::cube
