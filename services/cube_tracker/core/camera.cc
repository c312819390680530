#include "services/cube_tracker/core/camera.h"

#include <cmath>

#include <opencv2/calib3d.hpp>

#include "absl/strings/str_cat.h"

namespace kinemo::cube {

cv::Vec3d Pose::Rvec() const {
  cv::Vec3d r;
  cv::Rodrigues(R, r);
  return r;
}

Pose Pose::FromRvecTvec(const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  Pose p;
  cv::Rodrigues(rvec, p.R);
  p.t = tvec;
  return p;
}

Status ValidateCameraModel(const CameraModel& c) {
  if (c.width <= 0 || c.height <= 0 || c.width > 16384 || c.height > 16384) {
    return InvalidField("image_width/image_height", c.width, "x", c.height, " is not a valid image size");
  }
  if (!(c.K(0, 0) > 0 && c.K(1, 1) > 0)) return InvalidField("camera_matrix", "focal lengths must be positive");
  if (!(c.dist.empty() || c.dist.total() == 4 || c.dist.total() == 5 || c.dist.total() == 8 ||
        c.dist.total() == 12 || c.dist.total() == 14)) {
    return InvalidField("distortion_coefficients", c.dist.total(), " coefficients (expected 4, 5, 8, 12 or 14)");
  }
  return absl::OkStatus();
}

StatusOr<CameraModel> LoadCameraModel(const std::string& path) {
  CameraModel c;
  try {
    cv::FileStorage fs(path, cv::FileStorage::READ);
    if (!fs.isOpened()) return absl::NotFoundError(absl::StrCat(path, ": cannot open camera file"));
    fs["image_width"] >> c.width;
    fs["image_height"] >> c.height;
    cv::Mat K;
    fs["camera_matrix"] >> K;
    if (K.rows != 3 || K.cols != 3) return InvalidField(absl::StrCat(path, ": camera_matrix"), "missing or not 3x3");
    K.convertTo(K, CV_64F);
    c.K = cv::Matx33d(K);
    cv::Mat d;
    fs["distortion_coefficients"] >> d;
    if (d.empty()) d = cv::Mat::zeros(1, 5, CV_64F);
    d.convertTo(c.dist, CV_64F);
    c.dist = c.dist.reshape(1, 1);
    cv::Mat rv, tv;
    fs["surface_rvec"] >> rv;
    fs["surface_tvec"] >> tv;
    if (!rv.empty() || !tv.empty()) {
      if (rv.total() != 3 || tv.total() != 3) {
        return InvalidField(absl::StrCat(path, ": surface_rvec/surface_tvec"), "must both have 3 values");
      }
      rv.convertTo(rv, CV_64F);
      tv.convertTo(tv, CV_64F);
      c.surface = Pose::FromRvecTvec(cv::Vec3d(rv.ptr<double>()), cv::Vec3d(tv.ptr<double>()));
    }
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a readable OpenCV YAML file: ", e.what()));
  }
  Status s = ValidateCameraModel(c);
  if (!s.ok()) return Annotate(s, path);
  return c;
}

Status SaveCameraModel(const CameraModel& c, const std::string& path) {
  KINEMO_RETURN_IF_ERROR(ValidateCameraModel(c));
  try {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    if (!fs.isOpened()) return absl::PermissionDeniedError(absl::StrCat(path, ": cannot write camera file"));
    fs << "image_width" << c.width << "image_height" << c.height;
    fs << "camera_matrix" << cv::Mat(c.K);
    fs << "distortion_coefficients" << c.dist;
    if (c.surface) {
      fs << "surface_rvec" << cv::Mat(c.surface->Rvec());
      fs << "surface_tvec" << cv::Mat(c.surface->t);
    }
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat(path, ": writing failed: ", e.what()));
  }
  return absl::OkStatus();
}

CameraModel PinholeCamera(int width, int height, double hfov_deg) {
  CameraModel c;
  c.width = width;
  c.height = height;
  const double f = (width / 2.0) / std::tan(hfov_deg * CV_PI / 360.0);
  c.K = cv::Matx33d(f, 0, (width - 1) / 2.0, 0, f, (height - 1) / 2.0, 0, 0, 1);
  return c;
}

}  // namespace kinemo::cube
