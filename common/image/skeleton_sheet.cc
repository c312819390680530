#include "common/image/skeleton_sheet.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/image/png.h"
#include "common/motion/body_regions.h"
#include "common/motion/kinematics.h"

namespace kinemo::image {

StatusOr<std::string> RenderSkeletonSheetPng(const motion::Clip& clip, const SheetOptions& o) {
  if (clip.num_frames() == 0) return InvalidField("clip", "has no frames");
  if (o.panels < 1 || o.panels > 400) return InvalidField("panels", o.panels, " (1..400)");
  if (o.columns < 1) return InvalidField("columns", o.columns, " (>= 1)");
  if (o.panel_px < 64 || o.panel_px > 2048) return InvalidField("panel_px", o.panel_px, " (64..2048)");
  const motion::Skeleton& sk = clip.skeleton;
  const int n = std::min(o.panels, clip.num_frames());
  const int cols = std::min(o.columns, n);
  const int rows = (n + cols - 1) / cols;
  const int joints = sk.num_joints();
  const int h_axis = o.side_view ? 2 : 0;

  // World positions (joints and end sites) of the chosen frames.
  std::vector<int> frames(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    frames[static_cast<size_t>(i)] = n == 1 ? 0 : static_cast<int>(std::lround(
        static_cast<double>(i) * (clip.num_frames() - 1) / (n - 1)));
  }
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(joints)), ends(static_cast<size_t>(joints));
  std::vector<Eigen::Matrix3d> rot(static_cast<size_t>(joints));
  std::vector<std::vector<Eigen::Vector3d>> all_pos, all_end;
  double extent = 0;  // largest half-size of a figure around its root, for one scale across panels
  double y_lo = 1e300, y_hi = -1e300;
  for (int f : frames) {
    KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(sk, clip.frame(f), pos, rot));
    for (int j = 0; j < joints; ++j) {
      ends[static_cast<size_t>(j)] = motion::EndSiteWorldPosition(sk.joint(j), pos[static_cast<size_t>(j)],
                                                                   rot[static_cast<size_t>(j)]);
    }
    const double cx = pos[0][h_axis];
    for (int j = 0; j < joints; ++j) {
      for (const Eigen::Vector3d& p : {pos[static_cast<size_t>(j)], ends[static_cast<size_t>(j)]}) {
        extent = std::max(extent, std::abs(p[h_axis] - cx));
        y_lo = std::min(y_lo, p.y());
        y_hi = std::max(y_hi, p.y());
      }
    }
    all_pos.push_back(pos);
    all_end.push_back(ends);
  }
  const double span = std::max({2 * extent, y_hi - y_lo, 1e-9});
  const double scale = 0.85 * o.panel_px / span;
  const double y_mid = 0.5 * (y_lo + y_hi);

  const motion::BodyRegionMap regions = motion::MapBodyRegions(sk);
  auto keys = motion::FindKeyJoints(sk, regions);
  cv::Mat img(rows * o.panel_px, cols * o.panel_px, CV_8UC3, cv::Scalar(250, 250, 250));
  for (int i = 0; i < n; ++i) {
    const int px0 = (i % cols) * o.panel_px, py0 = (i / cols) * o.panel_px;
    cv::rectangle(img, {px0, py0}, {px0 + o.panel_px - 1, py0 + o.panel_px - 1}, {210, 210, 210}, 1);
    const auto& P = all_pos[static_cast<size_t>(i)];
    const auto& E = all_end[static_cast<size_t>(i)];
    const double cx = P[0][h_axis];
    auto to_px = [&](const Eigen::Vector3d& p) {
      return cv::Point(px0 + static_cast<int>(std::lround(o.panel_px / 2.0 + (p[h_axis] - cx) * scale)),
                       py0 + static_cast<int>(std::lround(o.panel_px / 2.0 - (p.y() - y_mid) * scale)));
    };
    for (int j = 0; j < joints; ++j) {
      const int parent = sk.joint(j).parent;
      const motion::BodyRegion r = regions.region[static_cast<size_t>(j)];
      const bool left = r == motion::BodyRegion::kLeftArm || r == motion::BodyRegion::kLeftHand ||
                        r == motion::BodyRegion::kLeftLeg;
      const cv::Scalar colour = left ? cv::Scalar(200, 90, 30) : cv::Scalar(40, 40, 40);
      if (parent >= 0) cv::line(img, to_px(P[static_cast<size_t>(parent)]), to_px(P[static_cast<size_t>(j)]), colour, 2, cv::LINE_AA);
      if (sk.joint(j).end_site) cv::line(img, to_px(P[static_cast<size_t>(j)]), to_px(E[static_cast<size_t>(j)]), colour, 2, cv::LINE_AA);
    }
    if (keys.ok()) {
      cv::circle(img, to_px(P[static_cast<size_t>(keys->head)]), std::max(3, o.panel_px / 40), {60, 60, 200}, cv::FILLED, cv::LINE_AA);
      for (int hand : {keys->left_hand, keys->right_hand}) {
        cv::circle(img, to_px(P[static_cast<size_t>(hand)]), std::max(2, o.panel_px / 60), {30, 150, 30}, cv::FILLED, cv::LINE_AA);
      }
    }
    char label[32];
    std::snprintf(label, sizeof label, "%.2f s", frames[static_cast<size_t>(i)] * clip.frame_time_s);
    cv::putText(img, label, {px0 + 6, py0 + 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {90, 90, 90}, 1, cv::LINE_AA);
  }
  return EncodePng({img.data, img.cols, img.rows, 3, img.step, true});
}

}  // namespace kinemo::image
