// The tracker on rendered sequences: the real cube textures drawn over real
// photographs (tests/data/images, from OpenCV's sample data) at scripted poses.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "common/testing/process.h"
#include "services/cube_tracker/core/tracker.h"
#include "services/cube_tracker/render/evaluation.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

CubeModel Model() {
  auto m = LoadCubeModel(kData + "/cube/vleo.cube");
  EXPECT_TRUE(m.ok()) << m.status();
  return *m;
}

struct SequenceRun {
  std::vector<TruthFrame> truth;
  std::vector<CubeState> states;
  TrackingReport report;
};

void TrackScriptInto(const std::string& name, const TrackerOptions& options, bool calibrated_surface, SequenceRun& run) {
  auto script = LoadRenderScript(kData + "/cube/" + name + ".json");
  EXPECT_TRUE(script.ok()) << script.status();
  auto renderer = SequenceRenderer::Create(Model(), *script, options);
  EXPECT_TRUE(renderer.ok()) << renderer.status();
  CameraModel camera = renderer->camera();
  if (!calibrated_surface) camera.surface.reset();
  auto tracker = CubeTracker::Create(Model(), camera, options);
  EXPECT_TRUE(tracker.ok()) << tracker.status();
  cv::Mat frame;
  for (int64_t i = 0; i < renderer->frame_count(); ++i) {
    TruthFrame t;
    Status rs = renderer->Next(&frame, &t);
    ASSERT_TRUE(rs.ok()) << rs;
    CubeState s;
    Status st = tracker->Process(frame, t.time_s, &s);
    EXPECT_TRUE(st.ok()) << st;
    run.truth.push_back(std::move(t));
    run.states.push_back(std::move(s));
  }
  run.report = EvaluateTracking(run.truth, run.states);
  if (const char* dbg = std::getenv("KINEMO_CUBE_DEBUG"); dbg != nullptr && name == dbg) {
    for (size_t i = 0; i < run.truth.size(); ++i) {
      const auto& t = run.truth[i];
      const auto& s = run.states[i];
      std::printf("%3zu T vis %d face %d yaw %8.2f int %6.3f pos %7.4f %7.4f h %.4f tilt %5.1f rest %d | "
                  "S vis %d face %d yaw %8.2f int %6.3f pos %7.4f %7.4f h %.4f tilt %5.1f lift %d m %d rms %.2f ev %zu/%zu\n",
                  i, t.visible, t.top_face, t.yaw_deg, t.intensity, t.position_m[0], t.position_m[1], t.height_m,
                  t.tilt_deg, t.resting, s.visible, s.top_face, s.yaw_deg, s.intensity, s.position_m[0],
                  s.position_m[1], s.height_m, s.tilt_deg, s.lifted, s.markers, s.reprojection_px, t.events.size(),
                  s.events.size());
    }
  }
  std::printf("[%s] %s\n", name.c_str(), run.report.Summary().c_str());
  for (const auto& note : run.report.event_notes) std::printf("  %s\n", note.c_str());
}

SequenceRun TrackScript(const std::string& name, const TrackerOptions& options = {},
                        bool calibrated_surface = true) {
  SequenceRun run;
  TrackScriptInto(name, options, calibrated_surface, run);
  return run;
}

void ExpectTargets(const TrackingReport& r) {
  EXPECT_GE(r.top_face_accuracy, 0.995);
  EXPECT_LE(r.yaw_err_median_deg, 2.0);
  EXPECT_LE(r.pos_err_median_m, 0.005);
  EXPECT_LE(r.intensity_err_max, 0.02);
  EXPECT_EQ(r.missed_events, 0);
  EXPECT_EQ(r.spurious_events, 0);
  EXPECT_LE(r.max_event_offset_frames, 3);
}

TEST(CubeTrackerSequence, RotateTwoTurns) {
  SequenceRun run = TrackScript("rotate_two_turns");
  ExpectTargets(run.report);
  EXPECT_GE(run.report.detection_rate, 0.95);
  // The thesis's potentiometer: one counter-clockwise turn reaches -1, then two
  // clockwise turns reach +1.
  double lowest = 0;
  for (const auto& s : run.states) lowest = std::min(lowest, s.intensity);
  EXPECT_NEAR(lowest, -1.0, 0.02);
  EXPECT_NEAR(run.states.back().intensity, 1.0, 0.02);
}

TEST(CubeTrackerSequence, LiftRotatePlace) {
  SequenceRun run = TrackScript("lift_rotate_place");
  ExpectTargets(run.report);
  auto count = [](const auto& frames, EventType type) {
    int n = 0;
    for (const auto& f : frames) {
      for (const auto& e : f.events) n += e.type == type;
    }
    return n;
  };
  // The first rest and the raising rotations launch; the lift without rotation does not.
  EXPECT_GE(count(run.truth, EventType::kActionLaunched), 3);
  EXPECT_GE(count(run.truth, EventType::kFaceChanged), 2);
  EXPECT_EQ(count(run.states, EventType::kActionLaunched), count(run.truth, EventType::kActionLaunched));
  EXPECT_EQ(count(run.states, EventType::kFaceChanged), count(run.truth, EventType::kFaceChanged));
}

TEST(CubeTrackerSequence, MovePath) {
  SequenceRun run = TrackScript("move_path");
  ExpectTargets(run.report);
  EXPECT_LE(run.report.pos_err_p95_m, 0.005);
  // The cube slides out of view and back: it is lost once and found again.
  // The hand covering part of the marker does not make it flicker (the truth
  // calls a marker more than 1 % under the hand hidden; ArUco often still reads
  // it, so the return is found up to 7 frames before the truth says so).
  int lost = 0, found = 0;
  for (const auto& s : run.states) {
    for (const auto& e : s.events) {
      lost += e.type == EventType::kLost;
      found += e.type == EventType::kFound;
    }
  }
  EXPECT_EQ(lost, 1);
  EXPECT_EQ(found, 2);
  EXPECT_GE(run.report.matched_visibility_events, 2);
  EXPECT_LE(run.report.spurious_visibility_events, 1);
}

}  // namespace
}  // namespace kinemo::cube

namespace kinemo::cube {
namespace {

// Garbage frames give an error for that frame only; tracking goes on.
TEST(CubeTrackerFrames, GarbageFramesFailAlone) {
  auto script = LoadRenderScript(kData + "/cube/rotate_two_turns.json");
  ASSERT_TRUE(script.ok()) << script.status();
  auto renderer = SequenceRenderer::Create(Model(), *script);
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  auto tracker = CubeTracker::Create(Model(), renderer->camera());
  ASSERT_TRUE(tracker.ok()) << tracker.status();
  cv::Mat frame;
  TruthFrame truth;
  CubeState state;
  ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
  std::vector<uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", frame, jpeg));
  ASSERT_TRUE(tracker->ProcessEncoded(jpeg, 0.0, &state).ok());
  EXPECT_TRUE(state.visible);
  EXPECT_EQ(state.top_face, truth.top_face);

  CubeState untouched = state;
  EXPECT_FALSE(tracker->Process(cv::Mat(), 0.033, &state).ok());
  cv::Mat small;
  cv::resize(frame, small, cv::Size(320, 240));
  Status s = tracker->Process(small, 0.033, &state);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(s.message()).find("320x240"), std::string::npos) << s;
  std::vector<uint8_t> cut(jpeg.begin(), jpeg.begin() + jpeg.size() / 2);
  EXPECT_FALSE(tracker->ProcessEncoded(cut, 0.033, &state).ok());
  // A PNG signature followed by garbage.
  std::vector<uint8_t> noise = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  for (int i = 0; i < 5000; ++i) noise.push_back(static_cast<uint8_t>(i * 7919u));
  EXPECT_FALSE(tracker->ProcessEncoded(noise, 0.033, &state).ok());
  EXPECT_FALSE(tracker->ProcessEncoded({}, 0.033, &state).ok());
  EXPECT_FALSE(tracker->ProcessRaw(std::span<const uint8_t>(jpeg.data(), 100), 640, 480, 1, 0.033, &state).ok());
  EXPECT_EQ(state.frame, untouched.frame);

  // The next good frame tracks on, without Lost or Found.
  ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
  cv::Mat gray;
  cv::cvtColor(frame, gray, cv::COLOR_BGR2GRAY);
  ASSERT_TRUE(tracker->ProcessRaw(std::span<const uint8_t>(gray.data, gray.total()), gray.cols, gray.rows, 1,
                                  truth.time_s, &state)
                  .ok());
  EXPECT_TRUE(state.visible);
  EXPECT_EQ(state.top_face, truth.top_face);
  for (const auto& e : state.events) EXPECT_NE(e.type, EventType::kLost);
}

// Through a real MJPG AVI file (compression artefacts), as `kinemo cube track` reads it.
TEST(CubeTrackerFrames, TracksARenderedVideoFile) {
  auto script = LoadRenderScript(kData + "/cube/lift_rotate_place.json");
  ASSERT_TRUE(script.ok()) << script.status();
  const kinemo::testing::TempDir scratch;  // unique per process: tests may run concurrently
  const std::string dir = scratch.path();
  const std::string video = dir + "/lrp.avi", truth_path = dir + "/lrp.json", cam_path = dir + "/lrp.yaml";
  std::vector<TruthFrame> truth;
  ASSERT_TRUE(SequenceRenderer::RenderToFiles(Model(), *script, video, truth_path, cam_path, &truth).ok());
  ASSERT_EQ(static_cast<int64_t>(truth.size()), script->frame_count());
  auto camera = LoadCameraModel(cam_path);
  ASSERT_TRUE(camera.ok()) << camera.status();
  auto tracker = CubeTracker::Create(Model(), *camera);
  ASSERT_TRUE(tracker.ok());
  cv::VideoCapture cap(video);
  ASSERT_TRUE(cap.isOpened());
  std::vector<CubeState> states;
  cv::Mat frame;
  for (size_t i = 0; cap.read(frame); ++i) {
    ASSERT_LT(i, truth.size()) << "the video has more frames than were rendered";
    CubeState s;
    ASSERT_TRUE(tracker->Process(frame, truth[i].time_s, &s).ok());
    states.push_back(s);
  }
  ASSERT_EQ(states.size(), truth.size());
  const TrackingReport r = EvaluateTracking(truth, states);
  std::printf("[lift_rotate_place.avi] %s\n", r.Summary().c_str());
  ExpectTargets(r);
  std::ifstream in(truth_path);
  EXPECT_TRUE(in.good());
}

}  // namespace
}  // namespace kinemo::cube

namespace kinemo::cube {
namespace {

// A single frame in which the cube appears 15 cm away (the image shifted) is
// dropped as a misdetection; the same jump seen twice in a row is accepted.
TEST(CubeTrackerFrames, ImplausibleJumpsNeedConfirmation) {
  auto script = LoadRenderScript(kData + "/cube/rotate_two_turns.json");
  ASSERT_TRUE(script.ok()) << script.status();
  auto renderer = SequenceRenderer::Create(Model(), *script);
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  auto tracker = CubeTracker::Create(Model(), renderer->camera());
  ASSERT_TRUE(tracker.ok()) << tracker.status();
  cv::Mat frame, shifted;
  TruthFrame truth;
  CubeState state;
  auto shift = [&](const cv::Mat& in) {
    const cv::Matx23d m(1, 0, 200, 0, 1, 0);  // 200 px right: about 15 cm at 40 cm
    cv::warpAffine(in, shifted, m, in.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    return shifted;
  };
  double t = 0;
  for (int i = 0; i < 10; ++i) {
    ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
    ASSERT_TRUE(tracker->Process(frame, t = truth.time_s, &state).ok());
  }
  ASSERT_TRUE(state.visible);
  const cv::Vec2d before = state.position_m;
  ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
  ASSERT_TRUE(tracker->Process(shift(frame), truth.time_s, &state).ok());
  EXPECT_FALSE(state.visible);
  EXPECT_EQ(tracker->jumps_rejected(), 1);
  EXPECT_LT(cv::norm(state.position_m - before), 0.002);
  EXPECT_TRUE(state.events.empty());
  ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
  ASSERT_TRUE(tracker->Process(frame, truth.time_s, &state).ok());
  EXPECT_TRUE(state.visible);
  EXPECT_LT(cv::norm(state.position_m - before), 0.002);
  EXPECT_TRUE(state.events.empty());
  // Twice in a row: the cube really moved.
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
    ASSERT_TRUE(tracker->Process(shift(frame), truth.time_s, &state).ok());
  }
  EXPECT_TRUE(state.visible);
  EXPECT_EQ(tracker->jumps_rejected(), 2);
  EXPECT_GT(cv::norm(state.position_m - before), 0.05);
}

// `initial_top_face` follows the model's face numbering (0 +Z, 1 -Z, 2 +X,
// 3 -X, 4 +Y, 5 -Y): the renderer puts that face up and the tracker, reading
// the markers, finds it on top (4 and 5 were swapped once).
TEST(CubeTrackerFrames, InitialTopFaceIsTheNumberedFace) {
  for (int face = 0; face < 6; ++face) {
    const std::string json = R"({"fps": 30, "width": 640, "height": 480, "hfov_deg": 60,
      "camera": {"distance_m": 0.4, "elevation_deg": 50, "azimuth_deg": -90, "look_at_m": [0, 0, 0.03]},
      "background": "../images/fruits.jpg", "noise_sigma": 1.0, "seed": 3, "initial_top_face": )" +
                             std::to_string(face) + R"(, "keys": [{"t_s": 0.0, "yaw_deg": 20}, {"t_s": 0.5}]})";
    auto script = ParseRenderScript(json, kData + "/cube");
    ASSERT_TRUE(script.ok()) << script.status();
    auto renderer = SequenceRenderer::Create(Model(), *script);
    ASSERT_TRUE(renderer.ok()) << renderer.status();
    auto tracker = CubeTracker::Create(Model(), renderer->camera());
    ASSERT_TRUE(tracker.ok()) << tracker.status();
    cv::Mat frame;
    TruthFrame truth;
    CubeState state;
    for (int64_t i = 0; i < renderer->frame_count(); ++i) {
      ASSERT_TRUE(renderer->Next(&frame, &truth).ok());
      ASSERT_TRUE(tracker->Process(frame, truth.time_s, &state).ok());
    }
    EXPECT_EQ(truth.top_face, face);
    EXPECT_EQ(state.top_face, face) << "face " << face;
  }
}

}  // namespace
}  // namespace kinemo::cube
