#include "common/gesture/kinematics.h"

#include <algorithm>
#include <cmath>

#include "common/motion/body_regions.h"
#include "common/motion/kinematics.h"

namespace kinemo::gesture {

StatusOr<HandTrack> ComputeHandTrack(const motion::Clip& clip) {
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  if (clip.num_frames() < 3) return InvalidField("clip", "needs at least 3 frames");
  const auto map = motion::MapBodyRegions(clip.skeleton);
  KINEMO_ASSIGN_OR_RETURN(motion::KeyJoints keys, motion::FindKeyJoints(clip.skeleton, map));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd world, motion::ComputeWorldPositions(clip));
  const double floor = std::min(world(0, 3 * keys.left_foot + 1), world(0, 3 * keys.right_foot + 1));
  const double height = world(0, 3 * keys.head + 1) - floor;
  if (!(height > 0)) return InvalidField("clip", "head is not above the feet in frame 0 (Y-up expected)");
  HandTrack t;
  t.dt = clip.frame_time_s;
  t.body_height = height;
  t.p.resize(clip.num_frames(), 6);
  t.p.leftCols(3) = world.middleCols(3 * keys.left_hand, 3) / height;
  t.p.rightCols(3) = world.middleCols(3 * keys.right_hand, 3) / height;
  t.h = ((world.col(3 * keys.left_hand + 1).array() - floor) +
         (world.col(3 * keys.right_hand + 1).array() - floor)) / height;
  return t;
}

Eigen::MatrixXd TimeDerivative(const Eigen::MatrixXd& x, double dt) {
  const Eigen::Index n = x.rows();
  Eigen::MatrixXd d(n, x.cols());
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index a = std::max<Eigen::Index>(0, i - 1), b = std::min(n - 1, i + 1);
    d.row(i) = (x.row(b) - x.row(a)) / ((b - a) * dt);
  }
  return d;
}

Eigen::VectorXd MeanHandSpeed(const Eigen::MatrixXd& v) {
  return 0.5 * (v.leftCols(3).rowwise().norm() + v.rightCols(3).rowwise().norm());
}

StatusOr<std::vector<KinematicSegment>> ComputeKinematicSegments(const motion::Clip& clip,
                                                                 const KinematicOptions& options) {
  KINEMO_ASSIGN_OR_RETURN(HandTrack hands, ComputeHandTrack(clip));
  const Eigen::MatrixXd v = TimeDerivative(hands.p, hands.dt);
  const Eigen::MatrixXd a = TimeDerivative(v, hands.dt);
  const Eigen::VectorXd speed = MeanHandSpeed(v);
  const Eigen::Index n = hands.p.rows();
  // Boundaries at threshold crossings.
  std::vector<Eigen::Index> starts{0};
  for (Eigen::Index i = 1; i < n; ++i) {
    const bool above = speed(i) >= options.speed_threshold_heights_per_s;
    const bool was = speed(i - 1) >= options.speed_threshold_heights_per_s;
    if (above != was) {
      if ((i - starts.back()) * hands.dt < options.min_segment_s) continue;  // merge short
      starts.push_back(i);
    }
  }
  if (starts.size() > 1 && (n - starts.back()) * hands.dt < options.min_segment_s) starts.pop_back();
  std::vector<KinematicSegment> out;
  constexpr double kEps = 1e-3;
  for (size_t k = 0; k < starts.size(); ++k) {
    const Eigen::Index s = starts[k];
    const Eigen::Index e = k + 1 < starts.size() ? starts[k + 1] : n;  // [s, e)
    const Eigen::Index len = e - s;
    double vnorm = 0, anorm = 0, cnorm = 0, hsum = 0;
    Eigen::Matrix<double, 1, 6> disp = Eigen::Matrix<double, 1, 6>::Zero();
    for (Eigen::Index i = s; i < e; ++i) {
      disp += hands.p.row(i) - hands.p.row(s);
      vnorm += v.row(i).norm();
      anorm += a.row(i).norm();
      const Eigen::Vector3d vl = v.row(i).head<3>().transpose(), vr = v.row(i).tail<3>().transpose();
      const Eigen::Vector3d al = a.row(i).head<3>().transpose(), ar = a.row(i).tail<3>().transpose();
      cnorm += std::sqrt(vl.cross(al).squaredNorm() + vr.cross(ar).squaredNorm());
      hsum += hands.h(i);
    }
    KinematicSegment seg;
    seg.start_s = s * hands.dt;
    seg.end_s = e * hands.dt;
    seg.params << std::log(len * hands.dt + kEps), std::log((disp / len).norm() + kEps),
        std::log(vnorm / len + kEps), std::log(anorm / len + kEps), std::log(cnorm / len + kEps),
        std::log(std::max(0.0, hsum / len) + kEps);
    out.push_back(seg);
  }
  return out;
}

Eigen::MatrixXd KinematicsAtTimes(const std::vector<KinematicSegment>& segments,
                                  const std::vector<double>& times_s) {
  Eigen::MatrixXd y(static_cast<Eigen::Index>(times_s.size()), 6);
  size_t k = 0;
  for (size_t t = 0; t < times_s.size(); ++t) {
    const double mid = times_s[t];
    while (k + 1 < segments.size() && segments[k].end_s <= mid) ++k;
    y.row(static_cast<Eigen::Index>(t)) = segments[k].params.transpose();
  }
  return y;
}

}  // namespace kinemo::gesture
