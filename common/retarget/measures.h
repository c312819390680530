// Measures of a retargeted clip: body regions from a rig's roles (for the
// foot checks of common/motion/feet.h and motion_check.h), bone directions
// by role, and how often a hand enters the torso.
#pragma once

#include <Eigen/Core>
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

}  // namespace kinemo::retarget
