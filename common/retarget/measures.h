// Measures of a retargeted clip: body regions from a rig's roles (for the
// foot checks of common/motion/feet.h and motion_check.h), bone directions
// by role, and how often a hand enters the torso.
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/skeleton.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::retarget {

// Regions from roles: trunk (hips, spine, chest, upper chest), head (neck,
// head, jaw), arm (shoulder, upper arm, forearm), hand (hand, fingers), leg
// (thigh, shin, foot, toes); other joints inherit their parent's.
motion::BodyRegionMap RegionsFromRoles(const Rig& rig);

// Torso capsule: the segment from the hips to the neck (or the topmost trunk
// bone), radius `radius_fraction` × the distance between the thighs' roots.
struct HandTorsoCheck {
  int frames = 0;
  int frames_inside = 0;  // frames in which a hand joint is inside the capsule
  double fraction() const { return frames ? static_cast<double>(frames_inside) / frames : 0; }
  double deepest_m = 0;   // largest depth of a hand inside, metres
};
StatusOr<HandTorsoCheck> CheckHandsInTorso(const motion::Clip& clip, const Rig& rig, double radius_fraction = 0.8);

// World direction (unit) of the bone of `role` (towards its next mapped
// role) in every frame; empty when the rig lacks either.
StatusOr<std::vector<Eigen::Vector3d>> BoneDirections(const motion::Clip& clip, const Rig& rig, Role role);

// Which way the trunk and the head face. Per frame, for the hips, the
// topmost trunk bone ("chest"), the neck and the head: the world directions
// of the rig's rest anatomical axes (RestAxes: the pelvis's for the hips, the
// upper body's for the others) turned by the bone's world rotation, i.e. up
// and forward as the rest pose defines them (a T-pose's head looks straight
// ahead); and, from joint positions alone (no rest convention involved), the
// left direction of the pelvis (right thigh -> left thigh) and of the
// shoulders (right upper arm -> left upper arm), and the neck -> head
// direction.
enum FacingPart { kFacingHips = 0, kFacingChest, kFacingNeck, kFacingHead, kNumFacingParts };
const char* FacingPartName(int part);
struct Facing {
  std::array<Eigen::Vector3d, kNumFacingParts> up, forward;
  Eigen::Vector3d pelvis_left, shoulder_left, neck_to_head;  // from positions
};
StatusOr<std::vector<Facing>> Facings(const motion::Clip& clip, const Rig& rig);

// Angle errors (degrees, p95 over frames) between the facings of a source
// clip and of its retargeting (same frame count), the source's world turned
// by `source_to_target` (Retargeter::world_axes()).
struct FacingErrors {
  std::array<double, kNumFacingParts> up_p95_deg{}, forward_p95_deg{};
  double pelvis_left_p95_deg = 0, shoulder_left_p95_deg = 0, neck_to_head_p95_deg = 0;
  double worst_p95_deg() const;
};
StatusOr<FacingErrors> CompareFacings(const motion::Clip& source, const Rig& source_rig, const motion::Clip& target,
                                      const Rig& target_rig, const Eigen::Matrix3d& source_to_target);

}  // namespace kinemo::retarget
