#include "common/motion/resample.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "common/motion/kinematics.h"

namespace kinemo::motion {

StatusOr<Clip> Resample(const Clip& clip, double target_fps) {
  constexpr double kMaxFps = 10000.0;
  if (!(target_fps > 0.0) || !(target_fps <= kMaxFps)) {
    return InvalidField("target_fps", target_fps, " must be in (0, ", kMaxFps, "]");
  }
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  const int n = clip.num_frames();
  const Skeleton& sk = clip.skeleton;
  const double dt = clip.frame_time_s;

  Clip out;
  out.skeleton = sk;
  out.frame_time_s = 1.0 / target_fps;
  if (n == 0) {
    out.frames.resize(0, sk.num_channels());
    return out;
  }
  const double span_s = (n - 1) * dt;
  const double last = std::floor(span_s * target_fps + 0.01);
  if (last >= 1e8) return InvalidField("target_fps", target_fps, " gives too many frames");
  const int m = static_cast<int>(last) + 1;
  out.frames.resize(m, sk.num_channels());

  for (int k = 0; k < m; ++k) {
    const double u = std::min(k / target_fps, span_s) / dt;
    int i = std::clamp(static_cast<int>(std::floor(u)), 0, std::max(n - 2, 0));
    const double w = n == 1 ? 0.0 : std::clamp(u - i, 0.0, 1.0);
    const int i1 = std::min(i + 1, n - 1);
    double* row = out.frames.data() + static_cast<Eigen::Index>(k) * out.frames.cols();
    const std::span<const double> reference =
        k == 0 ? clip.frame(i) : std::span<const double>(row - out.frames.cols(), static_cast<size_t>(out.frames.cols()));
    InterpolateFrame(sk, clip.frame(i), clip.frame(i1), w, reference,
                     std::span<double>(row, static_cast<size_t>(out.frames.cols())));
  }
  return out;
}

void InterpolateFrame(const Skeleton& skeleton, std::span<const double> f0, std::span<const double> f1, double w,
                      std::span<const double> reference, std::span<double> out) {
  // Linear interpolation of every channel first; Euler joints are then
  // overwritten by the slerp result.
  for (int c = 0; c < skeleton.num_channels(); ++c) {
    out[static_cast<size_t>(c)] = (1.0 - w) * f0[static_cast<size_t>(c)] + w * f1[static_cast<size_t>(c)];
  }
  for (const Joint& joint : skeleton.joints()) {
    if (!joint.has_euler_rotation()) continue;
    const Eigen::Quaterniond q0(LocalRotation(joint, f0));
    const Eigen::Quaterniond q1(LocalRotation(joint, f1));
    const Eigen::Matrix3d r = q0.slerp(w, q1).toRotationMatrix();
    Eigen::Vector3d ref;
    for (int a = 0; a < 3; ++a) ref[a] = reference[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(a)])];
    const Eigen::Vector3d e = MatrixToEuler(r, joint.rotation_axis, ref);
    for (int a = 0; a < 3; ++a) out[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(a)])] = e[a];
  }
}

}  // namespace kinemo::motion
