// Forward kinematics and Euler-angle helpers.
//
// Rotation channels compose intrinsically in the order the file lists them:
// for channels c1 c2 c3, R = R_c1(θ1) · R_c2(θ2) · R_c3(θ3), angles in
// degrees. A joint's world transform is parent_world · T(local translation) ·
// R (see skeleton.h for the local translation rule).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <span>
#include <vector>

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::motion {

// Rotation about axis 0/1/2 (X/Y/Z) by `angle_deg`.
Eigen::Matrix3d AxisRotation(int axis, double angle_deg);

// R = R_axes[0](angles[0]) · R_axes[1](angles[1]) · R_axes[2](angles[2]).
Eigen::Matrix3d EulerToMatrix(const std::array<int, 3>& axes, const Eigen::Vector3d& angles_deg);

// Inverse of EulerToMatrix for three distinct axes. Of the two Euler
// solutions (and their 360° multiples) returns the one nearest to
// `reference_deg`, so that a sequence stays continuous (unwrapped). In gimbal
// lock the first angle is taken from the reference.
Eigen::Vector3d MatrixToEuler(const Eigen::Matrix3d& rotation, const std::array<int, 3>& axes,
                              const Eigen::Vector3d& reference_deg);

// The joint's local rotation in a frame (identity when it has no rotation
// channels). `frame` holds all channel values of the frame.
Eigen::Matrix3d LocalRotation(const Joint& joint, std::span<const double> frame);

// Angular speed of joint j between two frames (its local rotation's change,
// the geodesic angle), in degrees per second; 0 without rotation channels.
double JointAngularSpeedDps(const Joint& joint, std::span<const double> prev, std::span<const double> cur,
                            double frame_time_s);

// World position and orientation of every joint for one frame, written into
// caller-owned spans of skeleton.num_joints() elements. Allocation-free.
// Fails only on size mismatches.
Status ComputeWorldPose(const Skeleton& skeleton, std::span<const double> frame,
                        std::span<Eigen::Vector3d> world_positions,
                        std::span<Eigen::Matrix3d> world_rotations);

// The same for the listed joints only (ascending indices; every listed
// joint's parent is listed too, e.g. from JointsWithAncestors); the others'
// entries are left as they are. For callers that need a few chains of a big
// skeleton (the feet of a 55-joint SMPL-X tree: 11 joints of 55).
Status ComputeWorldPoseOf(const Skeleton& skeleton, std::span<const double> frame, std::span<const int> joints,
                          std::span<Eigen::Vector3d> world_positions,
                          std::span<Eigen::Matrix3d> world_rotations);

// `joints` (any order, -1 entries ignored) and all their ancestors, ascending.
std::vector<int> JointsWithAncestors(const Skeleton& skeleton, std::span<const int> joints);

struct WorldPose {
  std::vector<Eigen::Vector3d> positions;  // per joint, file units
  std::vector<Eigen::Matrix3d> rotations;  // per joint, joint → world
};

// Convenience: allocates and fills a WorldPose for frame `f` of `clip`.
StatusOr<WorldPose> ComputeWorldPose(const Clip& clip, int f);

// World positions of every joint in every frame: a num_frames ×
// (3 · num_joints) matrix, joint j's x y z in columns 3j, 3j+1, 3j+2.
StatusOr<Eigen::MatrixXd> ComputeWorldPositions(const Clip& clip);

// World position of joint j's End Site (or of the joint itself when it has
// none) given its world pose.
inline Eigen::Vector3d EndSiteWorldPosition(const Joint& joint, const Eigen::Vector3d& position,
                                            const Eigen::Matrix3d& rotation) {
  return joint.end_site ? Eigen::Vector3d(position + rotation * *joint.end_site) : position;
}

}  // namespace kinemo::motion
