#include "common/motion/speed_limit.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/motion/kinematics.h"

namespace kinemo::motion {

StatusOr<UpperBodyJoints> FindUpperBodyJoints(const Skeleton& skeleton, const BodyRegionMap& regions) {
  KINEMO_ASSIGN_OR_RETURN(KeyJoints key, FindKeyJoints(skeleton, regions));
  UpperBodyJoints out;
  for (int j : {key.head, key.left_hand, key.right_hand}) {
    if (j < 0) continue;
    out.measured.push_back(j);
    if (j != key.head && skeleton.joint(j).parent >= 0) out.measured.push_back(skeleton.joint(j).parent);  // elbow
  }
  const int ends[] = {key.head, key.left_hand, key.right_hand};
  out.chain = JointsWithAncestors(skeleton, ends);
  const int feet[] = {key.left_foot, key.right_foot};
  const std::vector<int> legs = JointsWithAncestors(skeleton, feet);
  for (int j : out.chain) {
    if (std::find(legs.begin(), legs.end(), j) != legs.end()) continue;
    if (skeleton.joint(j).has_euler_rotation()) out.smoothed.push_back(j);
  }
  return out;
}

namespace {

// The fastest measured joint's speed into each frame f of [first, last] (m/s;
// 0 at frame 0), written into v.
void SpeedsInto(const Clip& clip, const UpperBodyJoints& joints, double meters_per_unit, int first, int last,
                std::vector<double>& v) {
  const Skeleton& sk = clip.skeleton;
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(sk.num_joints())), prev(pos.size());
  std::vector<Eigen::Matrix3d> rot(pos.size());
  const double scale = meters_per_unit / clip.frame_time_s;
  for (int f = std::max(0, first - 1); f <= last; ++f) {
    if (!ComputeWorldPoseOf(sk, clip.frame(f), joints.chain, pos, rot).ok()) return;
    if (f >= first) {
      double d = 0;
      if (f > 0) {
        for (int j : joints.measured) d = std::max(d, (pos[static_cast<size_t>(j)] - prev[static_cast<size_t>(j)]).norm());
      }
      v[static_cast<size_t>(f)] = d * scale;
    }
    std::swap(pos, prev);
  }
}

std::vector<double> Speeds(const Clip& clip, const UpperBodyJoints& joints, double meters_per_unit) {
  std::vector<double> out(static_cast<size_t>(clip.num_frames()), 0.0);
  if (!out.empty()) SpeedsInto(clip, joints, meters_per_unit, 0, clip.num_frames() - 1, out);
  return out;
}

}  // namespace

double MaxUpperBodySpeed(const Clip& clip, const UpperBodyJoints& joints, double meters_per_unit) {
  const std::vector<double> v = Speeds(clip, joints, meters_per_unit);
  return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
}

StatusOr<SpeedLimitReport> LimitUpperBodySpeed(Clip* clip, const UpperBodyJoints& joints,
                                               const SpeedLimitParams& params) {
  if (!(params.max_speed_m_s > 0 && params.max_speed_m_s <= 100)) {
    return InvalidField("max_speed_m_s", params.max_speed_m_s, " is not in (0, 100] m/s");
  }
  if (!(params.meters_per_unit > 0 && std::isfinite(params.meters_per_unit))) {
    return InvalidField("meters_per_unit", params.meters_per_unit, " must be > 0");
  }
  if (!(params.reach_s >= 0 && params.reach_s <= 2)) return InvalidField("reach_s", params.reach_s, " is not in [0, 2] s");
  if (!(params.max_passes >= 0 && params.max_passes <= 100)) {
    return InvalidField("max_passes", params.max_passes, " is not in [0, 100]");
  }
  KINEMO_RETURN_IF_ERROR(clip->Validate());
  SpeedLimitReport r;
  const int n = clip->num_frames();
  if (n < 3) return r;
  const Skeleton& sk = clip->skeleton;
  const int reach = static_cast<int>(std::lround(params.reach_s / clip->frame_time_s));
  std::vector<double> v = Speeds(*clip, joints, params.meters_per_unit);
  r.max_before_m_s = *std::max_element(v.begin(), v.end());
  for (double x : v) r.frames_over_before += x > params.max_speed_m_s;
  std::vector<double> weight(static_cast<size_t>(n));
  std::vector<Eigen::Quaterniond> q(static_cast<size_t>(n));
  std::vector<Eigen::VectorXd> original(static_cast<size_t>(n));  // rows as they came, once touched
  std::vector<std::pair<int, int>> runs;  // [first, last] of frames with weight > 0
  for (; r.passes < params.max_passes; ++r.passes) {
    KINEMO_RETURN_IF_ERROR(CheckCancel(params.cancel, "speed limit"));
    // Weights: a Hann window around every frame over the ceiling (the speed
    // into frame f is between f - 1 and f: both ends count).
    std::fill(weight.begin(), weight.end(), 0.0);
    bool over = false;
    for (int f = 1; f < n; ++f) {
      if (v[static_cast<size_t>(f)] <= params.max_speed_m_s) continue;
      over = true;
      for (int g = std::max(0, f - 1 - reach); g <= std::min(n - 1, f + reach); ++g) {
        const int d = g < f - 1 ? f - 1 - g : (g > f ? g - f : 0);
        const double w = reach > 0 ? 0.5 * (1 + std::cos(std::numbers::pi * d / (reach + 1))) : 1.0;
        weight[static_cast<size_t>(g)] = std::max(weight[static_cast<size_t>(g)], w);
      }
    }
    if (!over) break;
    runs.clear();
    for (int f = 0; f < n; ++f) {
      if (weight[static_cast<size_t>(f)] <= 0) continue;
      if (!runs.empty() && runs.back().second == f - 1) {
        runs.back().second = f;
      } else {
        runs.emplace_back(f, f);
      }
      if (original[static_cast<size_t>(f)].size() == 0) original[static_cast<size_t>(f)] = clip->frames.row(f).transpose();
    }
    for (int j : joints.smoothed) {
      const Joint& joint = sk.joint(j);
      for (const auto& [first, last] : runs) {
        // Every frame of the run reads its neighbours as they were before this pass.
        for (int f = std::max(0, first - 1); f <= std::min(n - 1, last + 1); ++f) {
          q[static_cast<size_t>(f)] = Eigen::Quaterniond(LocalRotation(joint, clip->frame(f)));
        }
        for (int f = first; f <= last; ++f) {
          const double w = weight[static_cast<size_t>(f)];
          // [1 2 1] / 4 of the neighbours, each on the same side as frame f.
          const Eigen::Quaterniond& c = q[static_cast<size_t>(f)];
          Eigen::Vector4d sum = 2 * c.coeffs();
          for (int g : {std::max(0, f - 1), std::min(n - 1, f + 1)}) {
            const Eigen::Quaterniond& o = q[static_cast<size_t>(g)];
            sum += (o.dot(c) < 0 ? -1.0 : 1.0) * o.coeffs();
          }
          Eigen::Quaterniond avg;
          avg.coeffs() = sum.normalized();
          const Eigen::Matrix3d m = c.slerp(w, avg).toRotationMatrix();
          Eigen::Vector3d ref;
          for (int a = 0; a < 3; ++a) ref[a] = clip->frames(f, joint.rotation_column[static_cast<size_t>(a)]);
          const Eigen::Vector3d e = MatrixToEuler(m, joint.rotation_axis, ref);
          for (int a = 0; a < 3; ++a) clip->frames(f, joint.rotation_column[static_cast<size_t>(a)]) = e[a];
        }
      }
    }
    // Only the speeds into and out of the changed frames moved.
    for (const auto& [first, last] : runs) SpeedsInto(*clip, joints, params.meters_per_unit, first, std::min(n - 1, last + 1), v);
  }
  r.max_after_m_s = *std::max_element(v.begin(), v.end());
  for (int f = 0; f < n; ++f) {
    const Eigen::VectorXd& o = original[static_cast<size_t>(f)];
    r.frames_changed += o.size() > 0 && clip->frames.row(f) != o.transpose();
  }
  return r;
}

}  // namespace kinemo::motion
