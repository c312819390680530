// Camera calibration with a ChArUco board, and the surface pose from a board
// lying flat on the table.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/status/status.h"
#include "services/cube_tracker/core/camera.h"

namespace kinemo::cube {

struct CharucoBoardSpec {
  int squares_x = 7;
  int squares_y = 5;
  double square_size_m = 0.035;
  double marker_size_m = 0.026;
  std::string dictionary = "DICT_5X5_100";
};
Status ValidateCharucoBoard(const CharucoBoardSpec& spec);

// The board as an 8-bit grey image, `pixels_per_square` per square, no margin.
StatusOr<cv::Mat> RenderCharucoBoard(const CharucoBoardSpec& spec, int pixels_per_square);

struct CalibrationResult {
  CameraModel camera;
  double rms_px = 0;
  int images_used = 0;
};

struct CalibrationOptions {
  // Estimate k1, k2, p1, p2 only (k3 = 0). A free k3 overfits the few views a
  // desk calibration has (on rendered views it trades ~1 % of focal length
  // against k2/k3); free it for wide-angle lenses.
  bool fix_k3 = true;
};

// Calibrates from views of the board (8-bit grey or BGR, all the same size).
// Views with fewer than 6 interpolated corners are skipped; needs 4 usable views.
StatusOr<CalibrationResult> CalibrateCharuco(const std::vector<cv::Mat>& images, const CharucoBoardSpec& spec,
                                             const CalibrationOptions& options = {});

// camera_from_surface from one view of the board lying on the table: origin at
// the board's first chessboard corner, x along its rows, z out of the board (up).
StatusOr<Pose> SurfaceFromCharuco(const cv::Mat& image, const CameraModel& camera, const CharucoBoardSpec& spec);

}  // namespace kinemo::cube
