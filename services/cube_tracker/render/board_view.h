// Calibration views for tests: a printed ChArUco board (RenderCharucoBoard)
// seen by a pinhole camera at a known pose, over a real photograph, with
// paper contrast and sensor noise.
#pragma once

#include <opencv2/core.hpp>

#include "services/cube_tracker/core/calibration.h"
#include "services/cube_tracker/core/camera.h"

namespace kinemo::cube {

// `board` is RenderCharucoBoard(spec, px_per_square); a one-square white
// margin is added around it. `camera_from_board`: board plane z = 0, origin at
// the board's centre, metres. Returns 8-bit grey of the camera's size.
cv::Mat RenderBoardView(const cv::Mat& board, const CharucoBoardSpec& spec, int px_per_square,
                        const CameraModel& camera, const Pose& camera_from_board, const cv::Mat& background_bgr,
                        cv::RNG& rng, double noise_sigma = 2.0);

// camera_from_board at `distance_m`, tilted about x then y, spun about the
// board normal (degrees), shifted by (dx_m, dy_m).
Pose BoardPose(double distance_m, double tilt_x_deg, double tilt_y_deg, double spin_deg, double dx_m, double dy_m);

}  // namespace kinemo::cube
