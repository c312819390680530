// Cube tracker throughput at 640x480 on one core: detection + pose + state per
// frame (CubeTracker::Process on BGR frames, grey conversion included), on 150
// consecutive frames of each scripted sequence rendered over real photographs
// (tests/data/images; no ../shared data is needed).
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

// One sequence at a time is kept (150 BGR frames, about 140 MB).
const Frames& LoadFrames(const std::string& script_name, int64_t first_frame) {
  static std::map<std::string, Frames>* cache = new std::map<std::string, Frames>();
  const std::string key = script_name + "@" + std::to_string(first_frame);
  auto it = cache->find(key);
  if (it != cache->end()) return it->second;
  cache->clear();
  Frames& f = (*cache)[key];
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
  // Consecutive frames, so that the tracker follows the cube as it would live.
  for (int64_t i = 0; i < renderer->frame_count() && i < first_frame + 150; ++i) {
    if (!renderer->Next(&frame, &truth).ok()) break;
    if (i >= first_frame) {
      f.bgr.push_back(frame.clone());
      f.time_s.push_back(truth.time_s);
    }
  }
  return f;
}

void TrackSequence(benchmark::State& state, const std::string& script, int64_t first_frame, bool roi) {
  cv::setNumThreads(1);
  const Frames& f = LoadFrames(script, first_frame);
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

// Frames 0-149: the first turn; 30-179: lift, roll, place; 250-399: the cube
// slides out of view and back (full-frame searches while it is away).
void BM_CubeTrack_RotateTwoTurns(benchmark::State& s) { TrackSequence(s, "rotate_two_turns", 0, true); }
void BM_CubeTrack_LiftRotatePlace(benchmark::State& s) { TrackSequence(s, "lift_rotate_place", 30, true); }
void BM_CubeTrack_MovePath(benchmark::State& s) { TrackSequence(s, "move_path", 250, true); }
void BM_CubeTrack_MovePath_FullFrame(benchmark::State& s) { TrackSequence(s, "move_path", 250, false); }
BENCHMARK(BM_CubeTrack_RotateTwoTurns)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CubeTrack_LiftRotatePlace)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CubeTrack_MovePath)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CubeTrack_MovePath_FullFrame)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace kinemo::cube
