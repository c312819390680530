// Motion transfer between rigs: rest-pose-relative world-rotation transfer
// (see docs/retarget.md).
//
// Both rigs name their bones with canonical roles (roles.h). For a role r
// played by source joint s and target joint t:
//   W_t(frame) = C · W_s(frame) · Cᵀ · A_r
// where W are world rotations relative to each rig's rest pose (the BVH
// convention: rest = identity), C turns the source's world axes into the
// target's (from the rest poses' left-right and up directions, so a rig
// facing -Z or lying in Z-up is handled), and A_r = F_s,r · F_t,rᵀ is the
// per-role rest alignment between the role's rest frames in the two rigs
// (F_s turned by C). A rest frame says what "as at rest" means for the role:
// the hips are the pelvis' anatomical axes and the trunk, neck and head the
// upper body's (RestAxes in rig.h: left from the thighs / upper arms, up the
// world's or, for a rest pose lying down like Bandai's, hips -> neck), so a
// trunk or head at rest in the source is at rest in the target, whatever the
// rigs' spine curvatures and neck leans; limbs are their bone direction
// (towards the next mapped role: upper arm -> forearm, hand -> middle1, ...)
// turned about it by an anatomical axis (arms: the upper body's forward;
// thighs and shins: the pelvis' forward; feet: its left), so a T-pose rig
// follows an A-pose one and the twist is defined even when the rest pose is
// not a pose (Bandai's). At a limb's end (toes, finger tips) A is the parent
// role's. Target joints without a role keep their rest rotation relative to
// their parent.
//
// The hips move by the source hips' displacement scaled by the ratio of leg
// lengths, about the floor (y = 0 of both files) with the standing height
// carried over: target = s·C·(p_s − h_s·up) + h_t·up, where h is each rig's
// rest hips height above its lowest foot point.
//
// The trunk: when the target lacks upper_chest (or chest) and the source has
// it, the target's topmost trunk bone follows the source's topmost one, so
// neck and shoulders hang where the source's do.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/motion/feet.h"
#include "common/motion/skeleton.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::retarget {

struct RetargetOptions {
  bool fingers = true;      // transfer finger bones when both rigs have them
  bool root_motion = true;  // move the hips (else they stay at the rest position)
  // Plant the feet on the target (common/motion/feet.h FootPlanter: standing
  // feet stay still, soles on y = 0) — the source's foot slide and the
  // rigs' different leg proportions would otherwise show. Skipped for a
  // target without legs and feet.
  bool plant_feet = true;
  // Frame time of the frames RetargetFrame will see (RetargetClip uses the
  // clip's); bounded to (0, 1] s.
  double frame_time_s = 1.0 / 30.0;
};

// A character's size against an adult's: its leg length (hip-knee-ankle)
// over 0.7 m (a short adult's), at most 1 and at least 0.2. Foot contacts and planting
// thresholds in metres (contact heights and speeds, lock distance, step
// height) are scaled by it for smaller characters (Godette's legs are
// 0.44 m, the VRM 1.0 test model's 0.40 m): a half-size character's step
// lifts its foot half as high. Adult-size rigs keep the thresholds as they are.
double CharacterSizeScale(const Rig& rig);
motion::FootContactParams ContactParamsFor(const Rig& rig);
motion::FootPlantParams PlantParamsFor(const Rig& rig);

class Retargeter {
 public:
  // `source_skeleton` is the skeleton of the clips to come (the one
  // `source` was built from by RigFromSkeleton: same joints, same order).
  static StatusOr<Retargeter> Create(const motion::Skeleton& source_skeleton, const Rig& source, const Rig& target,
                                     const RetargetOptions& options = {});

  // One frame: source channel values in, target channel values out
  // (target.skeleton.num_channels()). Euler angles are unwrapped against
  // the previous call's output; call Reset() between unrelated clips.
  // Allocation-free.
  Status RetargetFrame(std::span<const double> source_frame, std::span<double> target_frame);
  void Reset();
  bool plants_feet() const { return planter_ != nullptr; }

  // A whole clip (frame time kept).
  StatusOr<motion::Clip> RetargetClip(const motion::Clip& source);

  // Roles transferred, and roles of either rig left at rest.
  std::vector<std::string> MappedRoles() const;
  std::vector<std::string> UnmappedRoles() const;
  // Target leg length / source leg length, both in metres.
  double root_scale() const { return root_scale_m_; }
  const motion::Skeleton& target_skeleton() const { return target_; }
  // C: the source's world axes -> the target's.
  const Eigen::Matrix3d& world_axes() const { return axes_; }
  // Per target joint: the source joint it follows (-1 = none) and its rest
  // alignment A_r (identity for a joint that follows none), so that a caller
  // can form W_t = C · W_s · Cᵀ · A_r from source world rotations itself
  // (common/vmc: rotations without the Euler channels).
  int source_joint_of(int target_joint) const { return source_of_target_[static_cast<size_t>(target_joint)]; }
  const Eigen::Matrix3d& alignment(int target_joint) const { return align_[static_cast<size_t>(target_joint)]; }

 private:
  motion::Skeleton source_skeleton_;
  motion::Skeleton target_;
  std::vector<int> source_of_target_;         // per target joint: source joint or -1
  std::vector<Eigen::Matrix3d> align_;        // per target joint: A_r
  std::vector<bool> role_transferred_;        // per role
  std::vector<bool> role_present_;            // per role: either rig has it
  Eigen::Matrix3d axes_ = Eigen::Matrix3d::Identity();  // C
  double scale_ = 1;                          // leg ratio in units
  double root_scale_m_ = 1;
  double source_height_ = 0, target_height_ = 0;
  int source_hips_ = -1, target_hips_ = -1;
  bool root_motion_ = true;
  RetargetOptions options_;
  double target_mpu_ = 1;
  motion::FootPlantParams plant_params_;
  double frame_time_s_ = 1.0 / 30.0;
  motion::BodyRegionMap target_regions_;
  std::unique_ptr<motion::FootPlanter> planter_;
  Status MakePlanter(double frame_time_s);
  // Scratch (sized once).
  std::vector<Eigen::Vector3d> src_pos_, tgt_pos_;
  std::vector<Eigen::Matrix3d> src_rot_, tgt_rot_;
  std::vector<double> previous_;
  bool has_previous_ = false;
};

// Convenience: the whole clip on `target` from a clip in file units
// (`source_meters_per_unit`), the source's role map detected (or `choice`).
struct RetargetResult {
  motion::Clip clip;  // on target.skeleton
  std::vector<std::string> mapped_roles, unmapped_roles;
  double root_scale = 1;
};
StatusOr<RetargetResult> RetargetClip(const motion::Clip& source, double source_meters_per_unit, const Rig& target,
                                      const RetargetOptions& options = {}, const RoleMapChoice& source_choice = {});

}  // namespace kinemo::retarget
