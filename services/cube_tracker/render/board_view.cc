#include "services/cube_tracker/render/board_view.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace kinemo::cube {

cv::Mat RenderBoardView(const cv::Mat& board, const CharucoBoardSpec& spec, int px_per_square,
                        const CameraModel& camera, const Pose& pose, const cv::Mat& background, cv::RNG& rng,
                        double noise_sigma) {
  cv::Mat texture;
  cv::copyMakeBorder(board, texture, px_per_square, px_per_square, px_per_square, px_per_square,
                     cv::BORDER_CONSTANT, cv::Scalar(255));
  const double s = spec.square_size_m / px_per_square;  // metres per texture pixel
  // Texture pixel -> board plane (metres, centred) -> image.
  const cv::Matx33d S(s, 0, -s * texture.cols / 2.0, 0, s, -s * texture.rows / 2.0, 0, 0, 1);
  const cv::Matx33d Rt(pose.R(0, 0), pose.R(0, 1), pose.t[0], pose.R(1, 0), pose.R(1, 1), pose.t[1], pose.R(2, 0),
                       pose.R(2, 1), pose.t[2]);
  const cv::Matx33d H = camera.K * Rt * S;
  const cv::Size size(camera.width, camera.height);
  cv::Mat warped, mask;
  cv::warpPerspective(texture, warped, cv::Mat(H), size, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::warpPerspective(cv::Mat(texture.size(), CV_8UC1, cv::Scalar(255)), mask, cv::Mat(H), size, cv::INTER_LINEAR,
                      cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::Mat bg;
  if (background.channels() == 3) {
    cv::cvtColor(background, bg, cv::COLOR_BGR2GRAY);
  } else {
    bg = background;
  }
  cv::resize(bg, bg, size);
  cv::Mat w, m, b;
  warped.convertTo(w, CV_32F, 0.85, 20);  // paper under room light: not pure black and white
  mask.convertTo(m, CV_32F, 1.0 / 255);
  bg.convertTo(b, CV_32F);
  cv::Mat f = w.mul(m) + b.mul(1.0 - m);
  cv::Mat noise(size, CV_32F);
  rng.fill(noise, cv::RNG::NORMAL, 0, noise_sigma);
  f += noise;
  cv::Mat out;
  f.convertTo(out, CV_8U);
  return out;
}

Pose BoardPose(double distance_m, double tilt_x_deg, double tilt_y_deg, double spin_deg, double dx_m, double dy_m) {
  const double d2r = CV_PI / 180;
  cv::Matx33d Rx, Ry, Rz;
  cv::Rodrigues(cv::Vec3d(tilt_x_deg * d2r, 0, 0), Rx);
  cv::Rodrigues(cv::Vec3d(0, tilt_y_deg * d2r, 0), Ry);
  cv::Rodrigues(cv::Vec3d(0, 0, spin_deg * d2r), Rz);
  return Pose{Rx * Ry * Rz, cv::Vec3d(dx_m, dy_m, distance_m)};
}

}  // namespace kinemo::cube
