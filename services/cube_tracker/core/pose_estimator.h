// Detected ArUco markers → the cube's 6-DoF pose in camera coordinates.
//
// Every detected marker of the cube gives two IPPE candidates for the cube
// pose (a square seen in perspective has a mirror solution). Each candidate is
// scored by its reprojection error over the corners of every visible marker,
// faces that would point away from the camera are rejected, and among the
// candidates that explain the image equally well the one nearest the temporal
// prior (or, with no prior, the one that stands flattest on the surface) wins.
// The winner is refined by Levenberg–Marquardt over all visible corners.
#pragma once

#include <array>
#include <optional>
#include <vector>

#include <opencv2/aruco.hpp>
#include <opencv2/core.hpp>

#include "common/status/status.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_model.h"

namespace kinemo::cube {

struct DetectorOptions {
  // Adaptive-threshold window sizes (pixels) tried by ArUco: min, max, step.
  int threshold_window_min = 7;
  int threshold_window_max = 23;
  int threshold_window_step = 16;
  // Search a window around the predicted cube first (full frame on a miss).
  bool roi_tracking = true;
  // The window is the projected cube's bounding box grown by this fraction per side.
  double roi_margin = 0.6;
  // Without a prior (the cube unseen for longer than the tracker's hold-over), look for the cube's markers at half resolution
  // first and run the full-resolution detector only around them; when the half
  // image shows none, a full-resolution search of the whole frame runs every
  // `full_search_every` frames (a cube too small for the half image is found
  // within that many frames).
  bool coarse_search = true;
  int full_search_every = 4;
  // Sub-pixel corner refinement.
  bool subpixel_corners = true;
  // Candidates whose RMS reprojection error is within this factor (+0.5 px) of the
  // best are "equally good" and are ranked by the prior.
  double ambiguity_ratio = 1.5;
  // A pose whose RMS reprojection error exceeds this is rejected.
  double max_reprojection_px = 4.0;
};

struct PoseResult {
  bool found = false;
  Pose camera_from_cube;
  int markers = 0;            // markers of this cube used
  double rms_px = 0;          // RMS reprojection error after refinement
  std::array<bool, kNumFaces> face_seen{};
  cv::Rect search_window;     // where detection ran (the whole frame on a full search)
};

class CubePoseEstimator {
 public:
  static StatusOr<CubePoseEstimator> Create(const CubeModel& model, const CameraModel& camera,
                                            const DetectorOptions& options);

  // `gray` is 8-bit single channel of the camera's size. `prior` is the expected
  // pose (from the previous frame) or null; `up_in_camera` is the surface normal
  // in camera coordinates when known (used only to break ties without a prior).
  Status Estimate(const cv::Mat& gray, const Pose* prior, const cv::Vec3d* up_in_camera, PoseResult* out);

  const CubeModel& model() const { return model_; }
  const CameraModel& camera() const { return camera_; }

  // The correspondences behind the last pose (cube-frame corners, image corners).
  const std::vector<cv::Point3f>& object_points() const { return obj_; }
  const std::vector<cv::Point2f>& image_points() const { return img_; }
  const cv::Mat& camera_matrix() const { return K_; }
  const cv::Mat& distortion() const { return dist_; }

  // Projects the cube's 8 corners and returns their bounding box (clipped to the image).
  cv::Rect ProjectedBox(const Pose& camera_from_cube, double margin) const;

 private:
  CubePoseEstimator() = default;
  bool Detect(const cv::Mat& gray, const cv::Rect& window);
  bool Solve(const Pose* prior, const cv::Vec3d* up_in_camera, PoseResult* out);

  CubeModel model_;
  CameraModel camera_;
  DetectorOptions options_;
  cv::Ptr<cv::aruco::Dictionary> dictionary_;
  cv::Ptr<cv::aruco::DetectorParameters> params_;
  cv::Ptr<cv::aruco::DetectorParameters> coarse_params_;
  cv::Mat half_;
  int frames_since_full_ = 0;
  cv::Mat K_, dist_;
  std::array<Pose, kNumFaces> cube_from_marker_;
  // Scratch (reused frame to frame).
  std::vector<std::vector<cv::Point2f>> corners_, rejected_;
  std::vector<int> ids_;
  std::vector<cv::Point3f> obj_;
  std::vector<cv::Point2f> img_, proj_;
  std::vector<int> obj_face_;
};

}  // namespace kinemo::cube
