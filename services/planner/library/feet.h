// Foot planting (common/motion/feet.h) for motion made from a library's
// clips: every method (Gesture Controller, GMG, BodySpeech) plants with the
// library's scale and detects contacts from the level its clips stand at.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "common/motion/feet.h"
#include "common/motion/kinematics.h"
#include "services/planner/library/library.h"

namespace kinemo::planner {

// The level a library's soles stand at, in metres (EstimateGroundHeight over
// its clips at the library's scale, else 0.01 m per unit).
// FAILED_PRECONDITION when the skeleton has no legs to plant.
inline double LibraryMetersPerUnit(const Library& library) {
  return library.meters_per_unit > 0 ? library.meters_per_unit : 0.01;
}
inline StatusOr<double> LibraryGroundHeight(const Library& library) {
  KINEMO_ASSIGN_OR_RETURN(motion::FeetRig rig, motion::FeetRig::Find(library.skeleton, library.regions));
  std::vector<const motion::Clip*> clips;
  clips.reserve(library.clips.size());
  for (const LibraryClip& c : library.clips) clips.push_back(&c.clip);
  return motion::EstimateGroundHeight(clips, rig, LibraryMetersPerUnit(library));
}

// `params` with contact.meters_per_unit (the library's, else 0.01) and
// contact.ground_height_m (`ground`, from LibraryGroundHeight) filled in.
inline StatusOr<motion::FootPlantParams> LibraryFootPlantParams(const Library& library,
                                                                const StatusOr<double>& ground,
                                                                motion::FootPlantParams params) {
  if (!ground.ok()) return ground.status();
  params.contact.meters_per_unit = LibraryMetersPerUnit(library);
  params.contact.ground_height_m = *ground;
  return params;
}
inline StatusOr<motion::FootPlantParams> LibraryFootPlantParams(const Library& library,
                                                                motion::FootPlantParams params) {
  return LibraryFootPlantParams(library, LibraryGroundHeight(library), std::move(params));
}

// Where a pose of a library clip stands: the horizontal (x, z) midpoint of its
// two foot joints, in file units. Motion assembled from clips (GMG and
// BodySpeech pieces, Gesture Controller segments) joins them there rather than
// at joint 0, because the clips need not carry the body in joint 0: the
// Bandai takes keep joint_Root at the origin and move Hips, and stand up to
// half a metre apart (the "tired" takes at z = -48 cm), so joining at joint 0
// glided the whole body across every blend between them. Skeletons without
// feet fall back to joint 0's X and Z position channels. Not thread-safe (one
// per user); At() allocates nothing.
class StanceLocator {
 public:
  explicit StanceLocator(const Library& library)
      : library_(library),
        pos_(static_cast<size_t>(library.skeleton.num_joints())),
        rot_(static_cast<size_t>(library.skeleton.num_joints())) {
    StatusOr<motion::KeyJoints> key = motion::FindKeyJoints(library.skeleton, library.regions);
    if (key.ok()) {
      feet_ = {key->left_foot, key->right_foot};
      chain_ = motion::JointsWithAncestors(library.skeleton, feet_);  // only the legs are posed
    }
  }

  // Frame `frame` (rounded, clamped) of clip `clip`.
  Eigen::Vector2d At(int clip, double frame) {
    const motion::Clip& c = library_.clips[static_cast<size_t>(clip)].clip;
    const int f = std::clamp(static_cast<int>(std::lround(frame)), 0, c.num_frames() - 1);
    const auto values = c.frame(f);
    if (feet_[0] >= 0 && motion::ComputeWorldPoseOf(c.skeleton, values, chain_, pos_, rot_).ok()) {
      const Eigen::Vector3d mid = 0.5 * (pos_[static_cast<size_t>(feet_[0])] + pos_[static_cast<size_t>(feet_[1])]);
      return {mid.x(), mid.z()};
    }
    const motion::Joint& root = c.skeleton.joint(0);
    const auto channel = [&](int axis) {
      const int col = root.position_column[static_cast<size_t>(axis)];
      return col >= 0 ? values[static_cast<size_t>(col)] : 0.0;
    };
    return {channel(0), channel(2)};
  }

 private:
  const Library& library_;
  std::array<int, 2> feet_ = {-1, -1};
  std::vector<int> chain_;  // the feet and their ancestors
  std::vector<Eigen::Vector3d> pos_;
  std::vector<Eigen::Matrix3d> rot_;
};

}  // namespace kinemo::planner
