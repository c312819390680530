#include "common/motion/inertialize.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "common/motion/kinematics.h"

namespace kinemo::motion {
namespace {

double Quintic(double x0, double v0, double a0, double T, double tau) {
  if (tau >= T) return 0;
  const double T2 = T * T, T3 = T2 * T, T4 = T3 * T, T5 = T4 * T;
  const double A = -(a0 * T2 + 6 * v0 * T + 12 * x0) / (2 * T5);
  const double B = (3 * a0 * T2 + 16 * v0 * T + 30 * x0) / (2 * T4);
  const double C = -(3 * a0 * T2 + 12 * v0 * T + 20 * x0) / (2 * T3);
  const double t2 = tau * tau, t3 = t2 * tau;
  return A * t3 * t2 + B * t2 * t2 + C * t3 + 0.5 * a0 * t2 + v0 * tau + x0;
}

// The velocity at the last of three frames x0 (newest), x1, x2 of the
// parabola through them: with the second difference as the acceleration,
// the decay then continues the three frames shown. The backward difference
// x0 − x1 is the velocity half a frame earlier: it lacks half the
// acceleration, and the frames after the jump lost half their acceleration
// at once (a jerk step of a/(2·dt)). On held-out BEAT2 speech the wrists'
// mean jerk went 70.5 -> 69.1 m/s³ (Gesture Controller), 73.3 -> 71.5 (GMG).
double Velocity(double x0, double x1, double x2) { return 1.5 * x0 - 2 * x1 + 0.5 * x2; }

double WrapDeg(double d) {
  while (d > 180) d -= 360;
  while (d < -180) d += 360;
  return d;
}

// log(a · b⁻¹) as a rotation vector (radians).
Eigen::Vector3d RotationOffset(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  const Eigen::AngleAxisd aa(a * b.transpose());
  return aa.angle() * aa.axis();
}

}  // namespace

Inertializer::Inertializer(const Skeleton& skeleton) : skel_(skeleton) {
  for (int j = 0; j < skel_.num_joints(); ++j) {
    const Joint& joint = skel_.joint(j);
    const bool euler = joint.num_rotations == 3 && joint.has_euler_rotation();
    if (euler) euler_joints_.push_back(j);
    for (int c = 0; c < joint.num_channels(); ++c) {
      const int col = joint.first_channel + c;
      const bool rotation = IsRotation(joint.channels[static_cast<size_t>(c)]);
      if (euler && rotation) continue;
      scalar_cols_.push_back(col);
      scalar_is_rotation_.push_back(rotation ? 1 : 0);
    }
  }
  for (auto& h : hist_) h.assign(static_cast<size_t>(skel_.num_channels()), 0.0);
  rd_.resize(euler_joints_.size());
  sd_.resize(scalar_cols_.size());
  euler_at_rest_.assign(euler_joints_.size(), 0);
  scalar_at_rest_.assign(scalar_cols_.size(), 0);
}

void Inertializer::StartAtRest(std::span<const int> joints) {
  for (int j : joints) {
    if (j < 0 || j >= skel_.num_joints()) continue;
    for (size_t i = 0; i < euler_joints_.size(); ++i)
      if (euler_joints_[i] == j) euler_at_rest_[i] = 1;
    const Joint& joint = skel_.joint(j);
    for (size_t i = 0; i < scalar_cols_.size(); ++i)
      if (scalar_cols_[i] >= joint.first_channel && scalar_cols_[i] < joint.first_channel + joint.num_channels())
        scalar_at_rest_[i] = 1;
  }
}

void Inertializer::SetLastShown(std::span<const double> shown) {
  if (count_ > 0) std::copy(shown.begin(), shown.end(), hist_[0].begin());
}

void Inertializer::Reset() {
  count_ = 0;
  frames_ = k_ = 0;
}

void Inertializer::Start(std::span<const double> t1, std::span<const double> t2, std::span<const double> t3,
                         int frames, bool carry, int carry_frames) {
  if (count_ == 0) return;
  const std::array<std::span<const double>, 3> tgt = {t1, t2, t3};
  // Output history: fewer than three frames shown = at rest before them.
  const std::array<const std::vector<double>*, 3> out = {&hist_[0], &hist_[std::min(1, count_ - 1)],
                                                         &hist_[std::min(2, count_ - 1)]};
  for (size_t i = 0; i < euler_joints_.size(); ++i) {
    const Joint& joint = skel_.joint(euler_joints_[i]);
    std::array<Eigen::Vector3d, 3> r;
    for (size_t h = 0; h < 3; ++h) r[h] = RotationOffset(LocalRotation(joint, *out[h]), LocalRotation(joint, tgt[h]));
    // Rotation vectors near ±π can flip sign between frames: keep them on one side.
    for (size_t h = 1; h < 3; ++h) {
      const double n = r[h].norm();
      if (n > 1e-9 && r[h].dot(r[0]) < 0 && n > 2.0) r[h] -= (2 * 3.14159265358979323846 / n) * r[h];
    }
    for (int k = 0; k < 3; ++k) {
      Decay& d = rd_[i][static_cast<size_t>(k)];
      d.x0 = r[0](k);
      const bool rest = euler_at_rest_[i] || !carry;
      d.v0 = rest ? 0 : Velocity(r[0](k), r[1](k), r[2](k));
      d.a0 = rest ? 0 : r[0](k) - 2 * r[1](k) + r[2](k);
    }
  }
  for (size_t i = 0; i < scalar_cols_.size(); ++i) {
    const size_t c = static_cast<size_t>(scalar_cols_[i]);
    std::array<double, 3> d;
    for (size_t h = 0; h < 3; ++h) {
      d[h] = (*out[h])[c] - tgt[h][c];
      if (scalar_is_rotation_[i]) d[h] = WrapDeg(d[h]);
    }
    // A lone rotation: keep the three on one side of the ±180° wrap.
    if (scalar_is_rotation_[i])
      for (size_t h = 1; h < 3; ++h) d[h] = d[0] + WrapDeg(d[h] - d[0]);
    Decay& e = sd_[i];
    e.x0 = d[0];
    const bool rest = scalar_at_rest_[i] || !carry;
    e.v0 = rest ? 0 : Velocity(d[0], d[1], d[2]);
    e.a0 = rest ? 0 : d[0] - 2 * d[1] + d[2];
  }
  frames_ = std::max(1, frames);
  carry_frames_ = carry_frames > 0 ? std::min(frames_, carry_frames) : frames_;
  k_ = 0;
}

void Inertializer::Apply(std::span<const double> target, std::span<double> out) {
  if (out.data() != target.data()) std::copy(target.begin(), target.end(), out.begin());
  if (k_ < frames_) {
    ++k_;
    // Each difference decays along its quintic, τ = k_ frames after the
    // last frame shown before the jump.
    const double tau = k_;
    const double T = frames_, Tc = carry_frames_;
    // The difference over T, what it carried over Tc (one quintic when
    // Tc = T: it is linear in x0, v0, a0).
    const auto decay = [&](const Decay& d) {
      return Tc < T ? Quintic(d.x0, 0, 0, T, tau) + Quintic(0, d.v0, d.a0, Tc, tau) : Quintic(d.x0, d.v0, d.a0, T, tau);
    };
    for (size_t i = 0; i < euler_joints_.size(); ++i) {
      Eigen::Vector3d rv;
      for (int k = 0; k < 3; ++k) {
        const Decay& d = rd_[i][static_cast<size_t>(k)];
        rv(k) = decay(d);
      }
      const double angle = rv.norm();
      if (std::abs(angle) < 1e-12) continue;
      const Joint& joint = skel_.joint(euler_joints_[i]);
      const Eigen::Matrix3d rot = Eigen::AngleAxisd(angle, rv / angle).toRotationMatrix() * LocalRotation(joint, target);
      Eigen::Vector3d ref;
      for (int k = 0; k < 3; ++k) ref(k) = target[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(k)])];
      const Eigen::Vector3d ang = MatrixToEuler(rot, joint.rotation_axis, ref);
      for (int k = 0; k < 3; ++k) out[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(k)])] = ang(k);
    }
    for (size_t i = 0; i < scalar_cols_.size(); ++i) {
      const Decay& d = sd_[i];
      out[static_cast<size_t>(scalar_cols_[i])] += decay(d);
    }
  }
  // Shift the history (t−3 ← t−2 ← t−1 ← this frame).
  std::swap(hist_[2], hist_[1]);
  std::swap(hist_[1], hist_[0]);
  std::copy(out.begin(), out.end(), hist_[0].begin());
  ++count_;
}

LegsAtRestInertializer::LegsAtRestInertializer(const Skeleton& skeleton, std::span<const int> legs)
    : skel_(skeleton), join_(skeleton), still_(skeleton), still_row_(static_cast<size_t>(skeleton.num_channels())) {
  join_.StartAtRest(legs);
  std::vector<int> with_root(legs.begin(), legs.end());
  with_root.push_back(0);
  still_.StartAtRest(with_root);
  for (int j : legs) {
    if (j <= 0 || j >= skel_.num_joints()) continue;
    const Joint& joint = skel_.joint(j);
    if (joint.parent == 0 && joint.has_euler_rotation()) hips_.push_back(j);
  }
}

void LegsAtRestInertializer::Start(std::span<const double> t1, std::span<const double> t2,
                                   std::span<const double> t3, int frames, bool carry) {
  join_.Start(t1, t2, t3, frames, carry);
  still_.Start(t1, t2, t3, frames, carry);
}

void LegsAtRestInertializer::Apply(std::span<const double> target, std::span<double> out) {
  const bool turning = join_.active();
  join_.Apply(target, out);
  still_.Apply(target, still_row_);
  const Joint& root = skel_.joint(0);
  if (!turning || !root.has_euler_rotation()) return;
  const Eigen::Matrix3d turn = LocalRotation(root, out).transpose() * LocalRotation(root, still_row_);
  for (int h : hips_) {
    const Joint& hip = skel_.joint(h);
    Eigen::Vector3d ref;
    for (int a = 0; a < 3; ++a) ref[a] = out[static_cast<size_t>(hip.rotation_column[static_cast<size_t>(a)])];
    const Eigen::Vector3d e = MatrixToEuler(turn * LocalRotation(hip, out), hip.rotation_axis, ref);
    for (int a = 0; a < 3; ++a) out[static_cast<size_t>(hip.rotation_column[static_cast<size_t>(a)])] = e[a];
  }
  join_.SetLastShown(out);
}

}  // namespace kinemo::motion
