// Pinhole camera intrinsics (+ lens distortion) and, optionally, the pose of
// the surface the cube rests on, in an OpenCV FileStorage YAML file:
//
//   %YAML:1.0
//   image_width: 640
//   image_height: 480
//   camera_matrix: !!opencv-matrix {rows: 3, cols: 3, dt: d, data: [...]}
//   distortion_coefficients: !!opencv-matrix {rows: 1, cols: 5, dt: d, data: [...]}
//   # optional: the surface frame (z up, out of the table) in camera coordinates,
//   # as written by `kinemo cube calibrate --surface` from a board lying on the table
//   surface_rvec: !!opencv-matrix {rows: 3, cols: 1, dt: d, data: [...]}
//   surface_tvec: !!opencv-matrix {rows: 3, cols: 1, dt: d, data: [...]}
//
// This is the layout OpenCV's own calibration samples write, so their files load.
#pragma once

#include <optional>
#include <string>

#include <opencv2/core.hpp>

#include "common/status/status.h"

namespace kinemo::cube {

// A rigid transform: x_parent = R * x_child + t.
struct Pose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t{0, 0, 0};

  cv::Vec3d Apply(const cv::Vec3d& x) const { return R * x + t; }
  Pose Inverse() const { return Pose{R.t(), -(R.t() * t)}; }
  Pose operator*(const Pose& o) const { return Pose{R * o.R, R * o.t + t}; }
  cv::Vec3d Rvec() const;
  static Pose FromRvecTvec(const cv::Vec3d& rvec, const cv::Vec3d& tvec);
};

struct CameraModel {
  int width = 0;
  int height = 0;
  cv::Matx33d K = cv::Matx33d::eye();
  cv::Mat dist = cv::Mat::zeros(1, 5, CV_64F);  // k1 k2 p1 p2 k3 [...]
  // camera_from_surface: the surface frame (origin on the table, z up) in camera coordinates.
  std::optional<Pose> surface;
};

StatusOr<CameraModel> LoadCameraModel(const std::string& path);
Status SaveCameraModel(const CameraModel& camera, const std::string& path);
Status ValidateCameraModel(const CameraModel& camera);

// A pinhole camera with focal length from the horizontal field of view.
CameraModel PinholeCamera(int width, int height, double hfov_deg);

}  // namespace kinemo::cube
