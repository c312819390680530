// ChArUco calibration on views rendered over a real photograph
// (tests/data/images/aero3.jpg, from OpenCV's sample data): the board printed
// by RenderCharucoBoard is warped into a known pinhole camera at several
// poses, with sensor noise; the recovered intrinsics must match the rendering
// camera, and the table pose from one view must match the board's plane.
#include "services/cube_tracker/core/calibration.h"
#include "services/cube_tracker/render/board_view.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace kinemo::cube {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

TEST(Charuco, RecoversTheRenderingCameraIntrinsics) {
  const CharucoBoardSpec spec;  // 7x5, 35 mm squares, DICT_5X5_100
  const int px = 120;
  auto board = RenderCharucoBoard(spec, px);
  ASSERT_TRUE(board.ok()) << board.status();
  const cv::Mat background = cv::imread(kData + "/images/aero3.jpg");
  ASSERT_FALSE(background.empty());
  const CameraModel truth = PinholeCamera(640, 480, 62);
  cv::RNG rng(7);
  const Pose poses[] = {
      BoardPose(0.45, 0, 0, 0, 0, 0),           BoardPose(0.50, 30, 0, 5, 0.02, 0.01),
      BoardPose(0.50, -30, 0, -5, -0.02, 0),    BoardPose(0.48, 0, 32, 10, 0, -0.02),
      BoardPose(0.48, 0, -32, -10, 0.03, 0.02), BoardPose(0.55, 25, 25, 20, -0.03, 0.03),
      BoardPose(0.42, -20, 20, -15, 0.02, -0.03), BoardPose(0.60, 15, -25, 30, -0.05, 0.04),
      BoardPose(0.50, 45, 0, 0, 0, 0.03),         BoardPose(0.50, 0, -45, 0, -0.04, 0),
      BoardPose(0.40, -35, -30, 45, 0.06, 0.05),  BoardPose(0.65, 30, 35, -40, -0.08, -0.06),
  };
  std::vector<cv::Mat> images;
  for (const Pose& p : poses) images.push_back(RenderBoardView(*board, spec, px, truth, p, background, rng));
  auto result = CalibrateCharuco(images, spec);
  ASSERT_TRUE(result.ok()) << result.status();
  const CameraModel& c = result->camera;
  std::printf("calibrated from %d views: rms %.3f px, fx %.2f (truth %.2f), fy %.2f, cx %.2f (%.2f), cy %.2f (%.2f)\n",
              result->images_used, result->rms_px, c.K(0, 0), truth.K(0, 0), c.K(1, 1), c.K(0, 2), truth.K(0, 2),
              c.K(1, 2), truth.K(1, 2));
  std::printf("distortion k1 %.4f k2 %.4f p1 %.5f p2 %.5f k3 %.4f\n", c.dist.at<double>(0), c.dist.at<double>(1),
              c.dist.at<double>(2), c.dist.at<double>(3), c.dist.at<double>(4));
  EXPECT_EQ(result->images_used, 12);
  EXPECT_LT(result->rms_px, 0.5);
  // Measured: fx, fy about 0.8 % long, the principal point within 2.5 px.
  EXPECT_NEAR(c.K(0, 0) / truth.K(0, 0), 1.0, 0.015);
  EXPECT_NEAR(c.K(1, 1) / truth.K(1, 1), 1.0, 0.015);
  EXPECT_NEAR(c.K(0, 2), truth.K(0, 2), 6.0);
  EXPECT_NEAR(c.K(1, 2), truth.K(1, 2), 6.0);
  EXPECT_EQ(c.width, 640);
  EXPECT_EQ(c.height, 480);

  // The table from one view of the board lying on it: same plane (normal and
  // distance from the camera), whatever the board's own axis convention.
  const Pose table_pose = BoardPose(0.45, 40, 0, 0, 0, 0.02);
  const cv::Mat table = RenderBoardView(*board, spec, px, truth, table_pose, background, rng);
  auto surface = SurfaceFromCharuco(table, c, spec);
  ASSERT_TRUE(surface.ok()) << surface.status();
  const cv::Vec3d n_true = table_pose.R * cv::Vec3d(0, 0, 1);
  const cv::Vec3d n_est = surface->R * cv::Vec3d(0, 0, 1);
  const double angle_deg = std::acos(std::min(1.0, std::abs(n_true.dot(n_est)))) * 180 / CV_PI;
  const double d_true = std::abs(n_true.dot(table_pose.t));
  const double d_est = std::abs(n_est.dot(surface->t));
  std::printf("table plane: normal error %.3f deg, distance %.4f m (truth %.4f)\n", angle_deg, d_est, d_true);
  EXPECT_LT(angle_deg, 1.0);
  EXPECT_NEAR(d_est, d_true, 0.004);
}

TEST(Charuco, TooFewViewsAndBadBoardsAreErrors) {
  CharucoBoardSpec spec;
  auto none = CalibrateCharuco({cv::Mat(480, 640, CV_8UC1, cv::Scalar(128))}, spec);
  EXPECT_EQ(none.status().code(), absl::StatusCode::kFailedPrecondition);
  spec.marker_size_m = 0.05;
  auto bad = CalibrateCharuco({cv::Mat(480, 640, CV_8UC1, cv::Scalar(128))}, spec);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(bad.status().message()).find("board.marker_size_m"), std::string::npos);
}

}  // namespace
}  // namespace kinemo::cube
