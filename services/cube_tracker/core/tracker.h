// The cube tracker: frames in, cube state and gesture events out.
//
// Conventions (surface frame: origin on the table, z up out of the table):
// - top_face: the face whose outward normal is nearest the surface normal, with
//   hysteresis (`face_switch_margin_deg`).
// - yaw_deg: rotation about the surface normal of the top face's `right` axis
//   (FaceFrame), counter-clockwise seen from above is positive, unwrapped while
//   the top face stays the same; it restarts in (-180, 180] when the top face changes.
// - intensity (thesis §5.3.2): clockwise seen from above raises it, counter-clockwise
//   lowers it, `intensity_per_turn` per full turn (1: two turns go from -1 to 1),
//   saturating at ±1, counted only while the cube stands flat on the surface (not
//   lifted, top-face tilt below `flat_tilt_deg`), and reset to 0 when another face
//   comes up.
// - lifted / resting: the cube's lowest corner above the surface, with hysteresis.
// - ActionLaunched: the cube comes to rest (flat, on the surface) with a top face
//   other than the last launched one, i.e. after a raising rotation (or the first
//   rest ever).
// - Lost after `lost_after_frames` consecutive frames without the cube; Found on
//   the first frame that sees it again (and on the very first sighting).
//
// Without a calibrated surface (CameraModel::surface), the surface is taken from
// the first sighting: the cube is assumed to stand flat on it, and the face most
// facing the camera's image-up direction is on top.
//
// Not thread-safe; one tracker per camera stream. Process() allocates nothing in
// steady state when the caller reuses its CubeState.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "common/status/status.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/core/pose_estimator.h"

namespace kinemo::cube {

struct TrackerOptions {
  DetectorOptions detector;
  double face_switch_margin_deg = 3.0;
  double flat_tilt_deg = 20.0;
  double rest_height_m = 0.004;
  double lift_height_m = 0.012;
  double rest_tilt_deg = 8.0;
  // Frames in a row without the cube before Lost (the state holds meanwhile,
  // and the search follows the predicted position).
  int lost_after_frames = 5;
  // A cube seen near the surface (lowest corner below `snap_height_m`, tilt below
  // `snap_tilt_deg`) is refined as standing flat on it (x, y, yaw only) when that
  // explains the corners about as well as the free pose (RMS within
  // `snap_rms_ratio` x + 0.5 px). This removes the depth/tilt error of one marker.
  bool snap_to_surface = true;
  double snap_height_m = 0.015;
  double snap_tilt_deg = 15.0;
  double snap_rms_ratio = 1.5;
  // A cube standing on the surface in the previous frame stays snapped while
  // the standing pose's RMS error is below this (pixels), even when the free
  // pose fits better: motion blur stretches a single marker's corners and the
  // free pose explains that with a false tilt and lift.
  double snap_hold_rms_px = 6.0;
  double intensity_per_turn = 1.0;
  double intensity_event_step = 0.05;
  // A pose further from the last one than max_speed_mps allows (+ 2 cm) is taken
  // for a misdetection and dropped, unless the next frame confirms it.
  double max_speed_mps = 3.0;
  // One-euro filter (Casiez et al. 2012) on position and yaw; min_cutoff <= 0 disables it.
  double filter_min_cutoff_hz = 4.0;
  double filter_beta_position = 20.0;  // per m/s
  double filter_beta_yaw = 0.05;       // per deg/s
  double filter_dcutoff_hz = 1.0;
};
Status ValidateTrackerOptions(const TrackerOptions& options);

enum class EventType { kFound, kLost, kFaceChanged, kActionLaunched, kIntensityChanged };
const char* EventTypeName(EventType t);  // "found", "lost", "face_changed", ...

struct CubeEvent {
  EventType type = EventType::kFound;
  int64_t frame = 0;
  double time_s = 0;
  int top_face = -1;
  int previous_face = -1;  // FaceChanged only
  Action action = Action::kUnknown;
  double intensity = 0;
  double previous_intensity = 0;  // IntensityChanged only
  double last_seen_time_s = 0;    // Lost only
};

struct CubeState {
  int64_t frame = 0;
  double time_s = 0;
  bool visible = false;
  int top_face = -1;  // -1 until the cube has been seen
  Action action = Action::kUnknown;
  double yaw_deg = 0;
  double intensity = 0;
  cv::Vec2d position_m{0, 0};  // cube centre on the surface plane
  double height_m = 0;         // lowest corner above the surface
  double tilt_deg = 0;         // top face normal vs surface normal
  bool lifted = false;
  bool resting = false;  // on the surface, standing (not lifted, tilt < rest_tilt_deg)
  int markers = 0;
  std::array<bool, kNumFaces> faces_seen{};  // faces whose marker was used this frame
  double reprojection_px = 0;
  Pose camera_from_cube;  // valid when visible
  std::vector<CubeEvent> events;
};

class CubeTracker {
 public:
  static StatusOr<CubeTracker> Create(const CubeModel& model, const CameraModel& camera,
                                      const TrackerOptions& options = {});

  // One frame (8-bit grey or BGR, the camera's size) taken at `time_s`. On error
  // (empty, wrong size or type) the tracker's state is unchanged except the
  // frame counter, and `out` is not touched.
  Status Process(const cv::Mat& frame, double time_s, CubeState* out);
  // An encoded frame (JPEG or PNG) or raw 8-bit grey/BGR pixels of the camera's size.
  Status ProcessEncoded(std::span<const uint8_t> bytes, double time_s, CubeState* out);
  Status ProcessRaw(std::span<const uint8_t> pixels, int width, int height, int channels, double time_s,
                    CubeState* out);

  // Starts over (keeps the model, camera and a calibrated surface).
  void Reset();

  const CubeModel& model() const { return estimator_.model(); }
  const CameraModel& camera() const { return estimator_.camera(); }
  const TrackerOptions& options() const { return options_; }
  // camera_from_surface, once known.
  const std::optional<Pose>& surface() const { return surface_; }
  int64_t frames_seen() const { return next_frame_; }
  // Poses dropped as implausible jumps (see TrackerOptions::max_speed_mps).
  int64_t jumps_rejected() const { return jumps_rejected_; }

 private:
  struct OneEuro {
    bool init = false;
    double x = 0, dx = 0;
    double Filter(double value, double dt, double min_cutoff, double beta, double dcutoff);
  };
  explicit CubeTracker(CubePoseEstimator estimator, const TrackerOptions& options, const CameraModel& camera);
  void Update(const PoseResult& pose, double time_s, CubeState* out);
  void Emit(EventType t, CubeState* out);
  // Refines `camera_from_cube` as a cube standing on the surface with `face` up.
  bool SnapToSurface(int face, Pose* camera_from_cube, double* rms_px);

  CubePoseEstimator estimator_;
  TrackerOptions options_;
  std::optional<Pose> calibrated_surface_;
  std::optional<Pose> surface_;  // camera_from_surface
  cv::Mat gray_;
  cv::Mat decoded_;
  std::vector<cv::Point2f> snap_proj_;
  std::vector<double> snap_r_, snap_rp_;
  PoseResult pose_;

  int64_t next_frame_ = 0;
  // State carried from frame to frame.
  bool have_pose_ = false;
  Pose last_pose_;
  int64_t last_seen_frame_ = -1;
  double last_seen_time_s_ = 0;
  bool visible_ = false;
  bool ever_seen_ = false;
  int missed_ = 0;
  bool lost_reported_ = true;
  int top_face_ = -1;
  int last_launched_face_ = -1;
  bool lifted_ = false;
  bool resting_ = false;
  double yaw_raw_ = 0;     // unwrapped, unfiltered
  double yaw_deg_ = 0;     // unwrapped, filtered
  double yaw_anchor_ = 0;  // filtered yaw at the last flat frame
  bool yaw_valid_ = false;
  double intensity_ = 0;
  double last_event_intensity_ = 0;
  double last_time_s_ = 0;
  bool have_time_ = false;
  OneEuro fx_, fy_, fh_, fyaw_;
  cv::Vec3d velocity_{0, 0, 0};  // of the cube's centre in camera coordinates, m/s
  bool have_jump_ = false;       // a far pose awaiting confirmation
  cv::Vec3d jump_t_{0, 0, 0};
  int64_t jumps_rejected_ = 0;
  CubeState last_state_;
};

// Top face of a cube whose orientation in the surface frame is R (no hysteresis).
int TopFace(const cv::Matx33d& surface_from_cube_R);
// Yaw (degrees, (-180, 180]) of `face`'s right axis about the surface normal.
double FaceYawDeg(const cv::Matx33d& surface_from_cube_R, int face);

}  // namespace kinemo::cube
