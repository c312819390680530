// Full-body frames from body part samples: synchronised parts, root from the
// lower part's velocities, low-pass filter.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/motion/kinematics.h"
#include "services/planner/locomotion/locomotion.h"

namespace kinemo::planner::locomotion {
namespace {

Eigen::Matrix3d Yaw(double rad) { return Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitY()).toRotationMatrix(); }

void WriteEuler(const motion::Joint& joint, const Eigen::Matrix3d& r, const double* reference, std::span<double> out) {
  Eigen::Vector3d ref;
  for (int k = 0; k < 3; ++k) {
    const int col = joint.rotation_column[static_cast<size_t>(k)];
    ref[k] = reference ? reference[col] : out[static_cast<size_t>(col)];
  }
  const Eigen::Vector3d e = motion::MatrixToEuler(r, joint.rotation_axis, ref);
  for (int k = 0; k < 3; ++k) out[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(k)])] = e[k];
}

}  // namespace

void ComposeFrame(const LocomotionData& data, const std::vector<PartSample>& parts,
                  const std::vector<int>& part_of_chain, const RootState& root, const double* reference,
                  std::span<double> out) {
  const motion::Skeleton& s = data.library->skeleton;
  const PartSample& lower = parts[0];
  const double* base = data.FrameValues(lower.a);
  std::copy(base, base + s.num_channels(), out.begin());
  // Joints of the body parts (everything but the hips and its ancestors).
  for (int j = 0; j < s.num_joints(); ++j) {
    const motion::Joint& joint = s.joint(j);
    if (std::find(data.root_chain.begin(), data.root_chain.end(), j) != data.root_chain.end()) continue;
    const PartSample& ps = parts[static_cast<size_t>(part_of_chain[static_cast<size_t>(data.joint_chain[static_cast<size_t>(j)])])];
    const double* fa = data.FrameValues(ps.a);
    const double* fb = data.FrameValues(ps.b);
    for (int c = 0; c < joint.num_channels(); ++c) {
      const size_t col = static_cast<size_t>(joint.first_channel + c);
      out[col] = fa[col] + ps.alpha * (fb[col] - fa[col]);
    }
    if (joint.has_euler_rotation()) {
      const std::span<const double> sa(fa, static_cast<size_t>(s.num_channels()));
      const std::span<const double> sb(fb, static_cast<size_t>(s.num_channels()));
      Eigen::Matrix3d r;
      if (ps.alpha > 0) {
        const Eigen::Quaterniond qa(motion::LocalRotation(joint, sa));
        const Eigen::Quaterniond qb(motion::LocalRotation(joint, sb));
        r = qa.slerp(ps.alpha, qb).toRotationMatrix();
      } else {
        r = motion::LocalRotation(joint, sa);
      }
      WriteEuler(joint, r, reference, out);
    }
  }
  // Root: the hips' world transform at `root`, with the lower part's height
  // and heading-free orientation.
  const Eigen::Quaterniond free_a(Yaw(-data.heading_rad[static_cast<size_t>(lower.a)]) *
                                  data.hips_rotation[static_cast<size_t>(lower.a)].toRotationMatrix());
  const Eigen::Quaterniond free_b(Yaw(-data.heading_rad[static_cast<size_t>(lower.b)]) *
                                  data.hips_rotation[static_cast<size_t>(lower.b)].toRotationMatrix());
  const Eigen::Matrix3d r_des = Yaw(root.heading_rad) * free_a.slerp(lower.alpha, free_b).toRotationMatrix();
  const double height_m = data.hips_position_m[static_cast<size_t>(lower.a)].y() +
                          lower.alpha * (data.hips_position_m[static_cast<size_t>(lower.b)].y() -
                                         data.hips_position_m[static_cast<size_t>(lower.a)].y());
  const Eigen::Vector3d p_des = Eigen::Vector3d(root.position_m.x(), height_m, -root.position_m.y()) / data.meters_per_unit;
  // World transforms down the root chain (ancestors keep the lower frame's values).
  Eigen::Matrix3d rp = Eigen::Matrix3d::Identity();
  Eigen::Vector3d pp = Eigen::Vector3d::Zero();
  int mover = -1;
  Eigen::Matrix3d mover_parent_r = Eigen::Matrix3d::Identity();
  for (int j : data.root_chain) {
    const motion::Joint& joint = s.joint(j);
    const std::span<const double> frame(out.data(), out.size());
    if (j == data.hips) {
      if (joint.has_euler_rotation()) WriteEuler(joint, rp.transpose() * r_des, reference, out);
      const bool full_position =
          joint.position_column[0] >= 0 && joint.position_column[1] >= 0 && joint.position_column[2] >= 0;
      if (full_position) {
        const Eigen::Vector3d t = rp.transpose() * (p_des - pp);
        for (int a = 0; a < 3; ++a) {
          out[static_cast<size_t>(joint.position_column[static_cast<size_t>(a)])] =
              t[a] - (joint.position_relative_to_offset ? joint.offset[a] : 0.0);
        }
      } else if (mover >= 0) {
        const Eigen::Vector3d now = pp + rp * motion::LocalTranslation(joint, frame);
        const Eigen::Vector3d delta = mover_parent_r.transpose() * (p_des - now);
        const motion::Joint& mj = s.joint(mover);
        for (int a = 0; a < 3; ++a) out[static_cast<size_t>(mj.position_column[static_cast<size_t>(a)])] += delta[a];
      }
      break;
    }
    if (joint.position_column[0] >= 0 && joint.position_column[1] >= 0 && joint.position_column[2] >= 0) {
      mover = j;
      mover_parent_r = rp;
    }
    pp = pp + rp * motion::LocalTranslation(joint, frame);
    rp = rp * motion::LocalRotation(joint, frame);
  }
}

void LowPass(const motion::Skeleton& skeleton, double fps, double cutoff_hz, motion::FrameMatrix* frames) {
  const double sigma = fps * std::sqrt(std::log(2.0)) / (2 * std::numbers::pi * cutoff_hz);
  const int n = static_cast<int>(frames->rows());
  if (sigma < 0.25 || n < 3) return;
  const int radius = std::max(1, static_cast<int>(std::ceil(3 * sigma)));
  std::vector<double> kernel(static_cast<size_t>(2 * radius + 1));
  double sum = 0;
  for (int k = -radius; k <= radius; ++k) {
    kernel[static_cast<size_t>(k + radius)] = std::exp(-0.5 * k * k / (sigma * sigma));
    sum += kernel[static_cast<size_t>(k + radius)];
  }
  for (double& k : kernel) k /= sum;
  std::vector<double> column(static_cast<size_t>(n));
  for (int j = 0; j < skeleton.num_joints(); ++j) {
    const motion::Joint& joint = skeleton.joint(j);
    for (int k = 0; k < joint.num_rotations; ++k) {
      const int col = joint.rotation_column[static_cast<size_t>(k)];
      for (int t = 0; t < n; ++t) column[static_cast<size_t>(t)] = (*frames)(t, col);
      for (int t = 1; t + 1 < n; ++t) {
        double v = 0;
        for (int i = -radius; i <= radius; ++i) {
          v += kernel[static_cast<size_t>(i + radius)] * column[static_cast<size_t>(std::clamp(t + i, 0, n - 1))];
        }
        // Fade the filter in and out so the first and last frames stay exact.
        const double w = std::min({1.0, static_cast<double>(t) / radius, static_cast<double>(n - 1 - t) / radius});
        (*frames)(t, col) = column[static_cast<size_t>(t)] + w * (v - column[static_cast<size_t>(t)]);
      }
    }
  }
}

StatusOr<motion::Clip> TransitionMotion(const LocomotionGraph& graph, const Transition& tr) {
  const LocomotionData& d = graph.data();
  const motion::Skeleton& s = d.library->skeleton;
  motion::Clip clip;
  clip.skeleton = s;
  clip.frame_time_s = 1.0 / d.fps;
  clip.frames.resize(tr.total_frames + 1, s.num_channels());
  std::vector<int> part_of_chain(kNumChains, 0);
  for (size_t p = 0; p < graph.parts().size(); ++p) {
    for (Chain c : graph.parts()[p].chains) part_of_chain[static_cast<size_t>(c)] = static_cast<int>(p);
  }
  std::vector<PartSample> samples(graph.parts().size());
  RootState root;
  const Eigen::Vector3d& start = d.hips_position_m[static_cast<size_t>(tr.request)];
  root.position_m = Eigen::Vector2d(start.x(), -start.z());
  root.heading_rad = d.heading_rad[static_cast<size_t>(tr.request)];
  for (int t = 0; t <= tr.total_frames; ++t) {
    for (size_t p = 0; p < samples.size(); ++p) SamplePart(graph, tr, p, t, &samples[p]);
    double* row = clip.frames.data() + static_cast<Eigen::Index>(t) * clip.frames.cols();
    ComposeFrame(d, samples, part_of_chain, root, t > 0 ? row - clip.frames.cols() : nullptr,
                 std::span<double>(row, static_cast<size_t>(clip.frames.cols())));
    // Advance the root by the lower part's velocity at this frame.
    const PartSample& lo = samples[0];
    const Eigen::Vector2d v = d.velocity_m[static_cast<size_t>(lo.a)] +
                              lo.alpha * (d.velocity_m[static_cast<size_t>(lo.b)] - d.velocity_m[static_cast<size_t>(lo.a)]);
    const double turn = d.turn_rad[static_cast<size_t>(lo.a)] +
                        lo.alpha * (d.turn_rad[static_cast<size_t>(lo.b)] - d.turn_rad[static_cast<size_t>(lo.a)]);
    const double h = root.heading_rad;
    root.position_m += Eigen::Vector2d(std::cos(h) * v.x() - std::sin(h) * v.y(), std::sin(h) * v.x() + std::cos(h) * v.y());
    root.heading_rad = WrapAngle(h + turn);
  }
  LowPass(s, d.fps, graph.params().filter_cutoff_hz, &clip.frames);
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  return clip;
}

}  // namespace kinemo::planner::locomotion
