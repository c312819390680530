#include "common/motion/kinematics.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace kinemo::motion {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

// Returns x + 360·k closest to ref.
double UnwrapDeg(double x, double ref) { return x + 360.0 * std::round((ref - x) / 360.0); }

// c such that R_k(c) = m (m a rotation about axis k).
double AngleAboutAxis(const Eigen::Matrix3d& m, int k) {
  const int k1 = (k + 1) % 3;
  const int k2 = (k + 2) % 3;
  return std::atan2(m(k2, k1), m(k1, k1));
}

}  // namespace

Eigen::Matrix3d AxisRotation(int axis, double angle_deg) {
  const double a = angle_deg * kDegToRad;
  const double c = std::cos(a);
  const double s = std::sin(a);
  Eigen::Matrix3d r;
  switch (axis) {
    case 0:
      r << 1, 0, 0, 0, c, -s, 0, s, c;
      break;
    case 1:
      r << c, 0, s, 0, 1, 0, -s, 0, c;
      break;
    default:
      r << c, -s, 0, s, c, 0, 0, 0, 1;
      break;
  }
  return r;
}

Eigen::Matrix3d EulerToMatrix(const std::array<int, 3>& axes, const Eigen::Vector3d& angles_deg) {
  return AxisRotation(axes[0], angles_deg[0]) * AxisRotation(axes[1], angles_deg[1]) *
         AxisRotation(axes[2], angles_deg[2]);
}

Eigen::Vector3d MatrixToEuler(const Eigen::Matrix3d& r, const std::array<int, 3>& axes,
                              const Eigen::Vector3d& reference_deg) {
  const int i = axes[0];
  const int j = axes[1];
  const int k = axes[2];
  const double s = (j == (i + 1) % 3) ? 1.0 : -1.0;  // +1 for cyclic orders (XYZ, YZX, ZXY)
  const double sin_b = std::clamp(s * r(i, k), -1.0, 1.0);
  const double b = std::asin(sin_b);
  const double cos_b = std::hypot(r(j, k), r(k, k));
  const bool gimbal = cos_b < 1e-9;
  const double a = gimbal ? reference_deg[0] * kDegToRad : std::atan2(-s * r(j, k), r(k, k));

  // Two solutions: (a, b, c) and (a + π, π − b, c + π); c from the residual.
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  double best_dist = INFINITY;
  const int num_candidates = gimbal ? 1 : 2;
  for (int n = 0; n < num_candidates; ++n) {
    const double an = n == 0 ? a : a + std::numbers::pi;
    const double bn = n == 0 ? b : std::numbers::pi - b;
    const Eigen::Matrix3d residual = AxisRotation(j, bn * kRadToDeg).transpose() *
                                     AxisRotation(i, an * kRadToDeg).transpose() * r;
    const double cn = AngleAboutAxis(residual, k);
    Eigen::Vector3d e(UnwrapDeg(an * kRadToDeg, reference_deg[0]),
                      UnwrapDeg(bn * kRadToDeg, reference_deg[1]),
                      UnwrapDeg(cn * kRadToDeg, reference_deg[2]));
    const double dist = (e - reference_deg).squaredNorm();
    if (dist < best_dist) {
      best_dist = dist;
      best = e;
    }
  }
  return best;
}

Eigen::Matrix3d LocalRotation(const Joint& joint, std::span<const double> frame) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  for (int k = 0; k < joint.num_rotations; ++k) {
    r = r * AxisRotation(joint.rotation_axis[static_cast<size_t>(k)],
                         frame[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(k)])]);
  }
  return r;
}

double JointAngularSpeedDps(const Joint& joint, std::span<const double> prev, std::span<const double> cur,
                            double frame_time_s) {
  if (joint.num_rotations == 0) return 0.0;
  const Eigen::Matrix3d a = LocalRotation(joint, prev), b = LocalRotation(joint, cur);
  const double c = std::clamp(((a.transpose() * b).trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * kRadToDeg / frame_time_s;
}

namespace {

// The sizes ComputeWorldPose and ComputeWorldPoseOf need.
Status CheckPoseSpans(const Skeleton& skeleton, std::span<const double> frame, size_t positions,
                      size_t rotations) {
  const size_t n = static_cast<size_t>(skeleton.num_joints());
  if (frame.size() != static_cast<size_t>(skeleton.num_channels())) {
    return InvalidField("frame", frame.size(), " values, skeleton has ", skeleton.num_channels(),
                        " channels");
  }
  if (positions != n || rotations != n) {
    return InvalidField("world_positions/world_rotations", positions, "/", rotations,
                        " elements, skeleton has ", n, " joints");
  }
  return absl::OkStatus();
}

// Poses joint j from its parent's world pose (already computed).
void PoseJoint(const Skeleton& skeleton, std::span<const double> frame, int j,
               std::span<Eigen::Vector3d> world_positions, std::span<Eigen::Matrix3d> world_rotations) {
  const Joint& joint = skeleton.joint(j);
  const Eigen::Vector3d t = LocalTranslation(joint, frame);
  const Eigen::Matrix3d r = LocalRotation(joint, frame);
  const size_t i = static_cast<size_t>(j);
  if (joint.parent < 0) {
    world_positions[i] = t;
    world_rotations[i] = r;
  } else {
    const size_t p = static_cast<size_t>(joint.parent);
    world_positions[i] = world_positions[p] + world_rotations[p] * t;
    world_rotations[i] = world_rotations[p] * r;
  }
}

}  // namespace

Status ComputeWorldPose(const Skeleton& skeleton, std::span<const double> frame,
                        std::span<Eigen::Vector3d> world_positions,
                        std::span<Eigen::Matrix3d> world_rotations) {
  KINEMO_RETURN_IF_ERROR(CheckPoseSpans(skeleton, frame, world_positions.size(), world_rotations.size()));
  for (int j = 0; j < skeleton.num_joints(); ++j) PoseJoint(skeleton, frame, j, world_positions, world_rotations);
  return absl::OkStatus();
}

Status ComputeWorldPoseOf(const Skeleton& skeleton, std::span<const double> frame, std::span<const int> joints,
                          std::span<Eigen::Vector3d> world_positions,
                          std::span<Eigen::Matrix3d> world_rotations) {
  KINEMO_RETURN_IF_ERROR(CheckPoseSpans(skeleton, frame, world_positions.size(), world_rotations.size()));
  for (const int j : joints) PoseJoint(skeleton, frame, j, world_positions, world_rotations);
  return absl::OkStatus();
}

std::vector<int> JointsWithAncestors(const Skeleton& skeleton, std::span<const int> joints) {
  std::vector<bool> keep(static_cast<size_t>(skeleton.num_joints()), false);
  for (int j : joints) {
    for (int k = j; k >= 0 && k < skeleton.num_joints() && !keep[static_cast<size_t>(k)]; k = skeleton.joint(k).parent)
      keep[static_cast<size_t>(k)] = true;
  }
  std::vector<int> out;
  for (int j = 0; j < skeleton.num_joints(); ++j)
    if (keep[static_cast<size_t>(j)]) out.push_back(j);
  return out;
}

StatusOr<WorldPose> ComputeWorldPose(const Clip& clip, int f) {
  if (f < 0 || f >= clip.num_frames()) {
    return InvalidField("frame", f, " out of range [0, ", clip.num_frames(), ")");
  }
  WorldPose pose;
  pose.positions.resize(static_cast<size_t>(clip.skeleton.num_joints()));
  pose.rotations.resize(static_cast<size_t>(clip.skeleton.num_joints()));
  KINEMO_RETURN_IF_ERROR(
      ComputeWorldPose(clip.skeleton, clip.frame(f), pose.positions, pose.rotations));
  return pose;
}

StatusOr<Eigen::MatrixXd> ComputeWorldPositions(const Clip& clip) {
  const int n = clip.skeleton.num_joints();
  Eigen::MatrixXd out(clip.num_frames(), 3 * n);
  std::vector<Eigen::Vector3d> positions(static_cast<size_t>(n));
  std::vector<Eigen::Matrix3d> rotations(static_cast<size_t>(n));
  for (int f = 0; f < clip.num_frames(); ++f) {
    KINEMO_RETURN_IF_ERROR(ComputeWorldPose(clip.skeleton, clip.frame(f), positions, rotations));
    for (int j = 0; j < n; ++j)
      out.block<1, 3>(f, 3 * j) = positions[static_cast<size_t>(j)].transpose();
  }
  return out;
}

}  // namespace kinemo::motion
