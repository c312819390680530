#include "services/cube_tracker/core/calibration.h"

#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "services/cube_tracker/core/cube_model.h"

namespace kinemo::cube {
namespace {

StatusOr<cv::Ptr<cv::aruco::CharucoBoard>> MakeBoard(const CharucoBoardSpec& spec) {
  KINEMO_RETURN_IF_ERROR(ValidateCharucoBoard(spec));
  KINEMO_ASSIGN_OR_RETURN(int dict, DictionaryId(spec.dictionary));
  return cv::aruco::CharucoBoard::create(spec.squares_x, spec.squares_y, static_cast<float>(spec.square_size_m),
                                         static_cast<float>(spec.marker_size_m),
                                         cv::aruco::getPredefinedDictionary(dict));
}

cv::Mat Gray(const cv::Mat& m) {
  if (m.channels() == 1) return m;
  cv::Mat g;
  cv::cvtColor(m, g, m.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
  return g;
}

// Detects the board's chessboard corners; returns how many were found.
int DetectCorners(const cv::Mat& gray, const cv::Ptr<cv::aruco::CharucoBoard>& board, cv::Mat& corners,
                  cv::Mat& ids, const CameraModel* camera) {
  std::vector<std::vector<cv::Point2f>> mc;
  std::vector<int> mids;
  auto params = cv::aruco::DetectorParameters::create();
  cv::aruco::detectMarkers(gray, board->dictionary, mc, mids, params);
  if (mids.empty()) return 0;
  if (camera != nullptr) {
    return cv::aruco::interpolateCornersCharuco(mc, mids, gray, board, corners, ids, cv::Mat(camera->K),
                                                camera->dist);
  }
  return cv::aruco::interpolateCornersCharuco(mc, mids, gray, board, corners, ids);
}

}  // namespace

Status ValidateCharucoBoard(const CharucoBoardSpec& s) {
  if (s.squares_x < 3 || s.squares_y < 3 || s.squares_x > 40 || s.squares_y > 40) {
    return InvalidField("board.squares_x/squares_y", s.squares_x, "x", s.squares_y, " is not in 3..40");
  }
  if (!(s.square_size_m > 0 && s.marker_size_m > 0 && s.marker_size_m < s.square_size_m)) {
    return InvalidField("board.marker_size_m", "must be positive and smaller than square_size_m");
  }
  KINEMO_ASSIGN_OR_RETURN(int n, DictionarySize(s.dictionary));
  const int needed = s.squares_x * s.squares_y / 2;
  if (n < needed) {
    return InvalidField("board.dictionary", s.dictionary, " has ", n, " markers; the board needs ", needed);
  }
  return absl::OkStatus();
}

StatusOr<cv::Mat> RenderCharucoBoard(const CharucoBoardSpec& spec, int pixels_per_square) {
  if (pixels_per_square < 10 || pixels_per_square > 1000) {
    return InvalidField("pixels_per_square", pixels_per_square, " is not in 10..1000");
  }
  KINEMO_ASSIGN_OR_RETURN(auto board, MakeBoard(spec));
  try {
    cv::Mat img;
    board->draw(cv::Size(spec.squares_x * pixels_per_square, spec.squares_y * pixels_per_square), img, 0, 1);
    return img;
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("charuco board: ", e.what()));
  }
}

StatusOr<CalibrationResult> CalibrateCharuco(const std::vector<cv::Mat>& images, const CharucoBoardSpec& spec,
                                             const CalibrationOptions& options) {
  KINEMO_ASSIGN_OR_RETURN(auto board, MakeBoard(spec));
  if (images.empty()) return InvalidField("images", "none given");
  const cv::Size size = images[0].size();
  CalibrationResult result;
  try {
    std::vector<cv::Mat> all_corners, all_ids;
    for (size_t i = 0; i < images.size(); ++i) {
      if (images[i].empty() || images[i].size() != size) {
        return InvalidField(absl::StrCat("images[", i, "]"), "empty or not ", size.width, "x", size.height);
      }
      cv::Mat corners, ids;
      if (DetectCorners(Gray(images[i]), board, corners, ids, nullptr) >= 6) {
        all_corners.push_back(corners);
        all_ids.push_back(ids);
      }
    }
    if (all_corners.size() < 4) {
      return absl::FailedPreconditionError(absl::StrCat("calibration: the board was found in ", all_corners.size(),
                                                        " of ", images.size(), " images; need at least 4"));
    }
    cv::Mat K, dist;
    std::vector<cv::Mat> rvecs, tvecs;
    result.rms_px = cv::aruco::calibrateCameraCharuco(all_corners, all_ids, board, size, K, dist, rvecs, tvecs,
                                                      options.fix_k3 ? cv::CALIB_FIX_K3 : 0);
    result.camera.width = size.width;
    result.camera.height = size.height;
    result.camera.K = cv::Matx33d(K);
    dist.convertTo(result.camera.dist, CV_64F);
    result.camera.dist = result.camera.dist.reshape(1, 1);
    result.images_used = static_cast<int>(all_corners.size());
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("calibration: OpenCV: ", e.what()));
  }
  return result;
}

StatusOr<Pose> SurfaceFromCharuco(const cv::Mat& image, const CameraModel& camera, const CharucoBoardSpec& spec) {
  KINEMO_ASSIGN_OR_RETURN(auto board, MakeBoard(spec));
  if (image.empty() || image.cols != camera.width || image.rows != camera.height) {
    return InvalidField("image", "empty or not the camera's size");
  }
  try {
    cv::Mat corners, ids;
    if (DetectCorners(Gray(image), board, corners, ids, &camera) < 6) {
      return absl::FailedPreconditionError("surface: fewer than 6 board corners found");
    }
    cv::Vec3d rvec, tvec;
    if (!cv::aruco::estimatePoseCharucoBoard(corners, ids, board, cv::Mat(camera.K), camera.dist, rvec, tvec)) {
      return absl::FailedPreconditionError("surface: board pose could not be estimated");
    }
    return Pose::FromRvecTvec(rvec, tvec);
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("surface: OpenCV: ", e.what()));
  }
}

}  // namespace kinemo::cube
