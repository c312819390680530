// Ground truth for the cube tracker: the textured cube drawn at known poses
// over a real photograph, seen by a pinhole camera, with sensor noise, motion
// blur, lighting changes and a hand that partly hides the cube.
//
// A script (JSON) sets the camera and keyframes of the cube's pose:
//   {
//     "name": "lift_rotate_place", "fps": 30, "width": 640, "height": 480, "hfov_deg": 60,
//     "camera": {"distance_m": 0.4, "elevation_deg": 45, "azimuth_deg": -90, "look_at_m": [0, 0, 0.03]},
//     "background": "../images/building.jpg",   (relative to the script file)
//     "initial_top_face": 0, "noise_sigma": 2.0, "motion_blur_samples": 3, "seed": 1,
//     "keys": [ {"t_s": 0, "x_m": 0, "y_m": 0, "lift_m": 0, "yaw_deg": 0, "roll_x_deg": 0,
//                "roll_y_deg": 0, "hand": 0, "light": 1, "blur_px": 0}, ... ]
//   }
// Bounds: keys' t_s in [0, 600] s and increasing, at most 36000 frames,
// width and height in 64..4096 px, fps in (0, 240], positions within 10 m,
// angles within ±3600°, blur_px in [0, 100], light in [0, 10], noise_sigma
// in [0, 100], camera distance in (0, 100] m.
// A key's missing fields keep the previous key's values; between keys values
// move with smooth (ease-in-out) interpolation. The cube's orientation in the
// surface frame (z up) is Rz(yaw) · Rx(roll_x) · Ry(roll_y) · R0, where R0 puts
// `initial_top_face` up; its lowest corner is `lift_m` above the table.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/status/status.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/core/tracker.h"

namespace kinemo::cube {

// Bounds of a script (ParseRenderScript refuses anything beyond them, naming
// the field): what one render writes is limited.
inline constexpr double kMaxRenderDurationS = 600;    // keys[i].t_s in [0, 600]
inline constexpr std::int64_t kMaxRenderFrames = 36000;  // duration × fps + 1
inline constexpr int kMinRenderSizePx = 64;           // width, height in 64..4096
inline constexpr int kMaxRenderSizePx = 4096;

struct RenderKey {
  double t_s = 0;
  double x_m = 0, y_m = 0, lift_m = 0;
  double yaw_deg = 0, roll_x_deg = 0, roll_y_deg = 0;
  double hand = 0;   // > 0.5: a hand holds the cube (thumb and finger over its sides)
  double light = 1;  // global brightness gain
  double blur_px = 0;  // Gaussian blur sigma of the whole frame (defocus)
};

struct RenderScript {
  std::string name = "sequence";
  double fps = 30;
  int width = 640;
  int height = 480;
  double hfov_deg = 60;
  double camera_distance_m = 0.4;
  double camera_elevation_deg = 45;
  double camera_azimuth_deg = -90;
  cv::Vec3d look_at_m{0, 0, 0.03};
  std::string background;  // absolute, or relative to the script's directory once parsed
  int initial_top_face = 0;
  double noise_sigma = 2.0;
  int motion_blur_samples = 3;
  uint32_t seed = 1;
  std::vector<RenderKey> keys;

  double duration_s() const { return keys.empty() ? 0 : keys.back().t_s; }
  int64_t frame_count() const;
};

// Parses a script; a relative `background` is resolved against `base_dir`.
// Errors are INVALID_ARGUMENT naming the field ("keys[3].t_s: ..."): numbers
// must be finite, integers in their range, key times increasing in
// 0..kMaxRenderDurationS, and within the bounds above.
StatusOr<RenderScript> ParseRenderScript(const std::string& json_text, const std::string& base_dir);
StatusOr<RenderScript> LoadRenderScript(const std::string& path);

// The truth of one frame, in the tracker's conventions (see tracker.h).
struct TruthFrame {
  int64_t frame = 0;
  double time_s = 0;
  bool visible = false;   // a marker fully in view, facing the camera (< 80 deg), < 1 % under the hand
  int visible_markers = 0;
  int top_face = -1;
  Action action = Action::kUnknown;
  double yaw_deg = 0;
  double intensity = 0;
  cv::Vec2d position_m{0, 0};
  double height_m = 0;  // lowest corner above the table
  double tilt_deg = 0;
  bool resting = false;
  Pose camera_from_cube;
  std::vector<CubeEvent> events;
};

class SequenceRenderer {
 public:
  static StatusOr<SequenceRenderer> Create(const CubeModel& model, const RenderScript& script,
                                           const TrackerOptions& conventions = {});

  int64_t frame_count() const { return script_.frame_count(); }
  // The camera (intrinsics, and the surface pose as a table calibration would give it).
  const CameraModel& camera() const { return camera_; }
  const RenderScript& script() const { return script_; }

  // Renders frames in order (truth events depend on the previous frames).
  Status Next(cv::Mat* bgr, TruthFrame* truth);

  // Renders the whole script to an MJPG AVI and a truth JSON file (an empty
  // truth or camera path: not written); `truth`, when given, receives the truth
  // of every frame as well (what a second renderer would give, without
  // drawing the frames again).
  static Status RenderToFiles(const CubeModel& model, const RenderScript& script, const std::string& video_path,
                              const std::string& truth_path, const std::string& camera_path,
                              std::vector<TruthFrame>* truth = nullptr);

 private:
  SequenceRenderer() = default;
  Pose CubeAt(double t_s, RenderKey* key) const;
  void Draw(const Pose& world_from_cube, const RenderKey& key, cv::Mat3f* acc, cv::Mat1b* hand_mask) const;

  CubeModel model_;
  RenderScript script_;
  TrackerOptions conv_;
  CameraModel camera_;
  Pose camera_from_world_;
  cv::Mat3b background_;
  std::array<cv::Mat1b, kNumFaces> textures_;
  cv::RNG rng_;
  int64_t next_ = 0;
  // Truth state.
  int top_face_ = -1;
  double yaw_unwrapped_ = 0;
  double yaw_anchor_ = 0;
  bool yaw_valid_ = false;
  double intensity_ = 0;
  double last_event_intensity_ = 0;
  bool visible_ = false;
  int missed_ = 0;
  int last_launched_face_ = -1;
};

// The truth as JSON (one object; "frames" holds one entry per frame).
std::string TruthToJson(const CameraModel& camera, const std::vector<TruthFrame>& frames);

}  // namespace kinemo::cube
