// Motion of any rig kinemo reads (SMPL-X, Bandai, CMU, Mixamo, a glTF/VRM
// skin's skeleton, ...) as the pose of a normalized humanoid, the form the
// VMC protocol carries (docs/vmc.md):
//
//   - bones named by humanoid role (common/retarget/roles.h): Unity's
//     HumanBodyBones names ("LeftUpperArm") or VRM 1.0's ("leftUpperArm");
//   - local rotations of a humanoid whose rest pose is the VRM T-pose with
//     identity rotations: facing +Z, arms, hands and fingers along ±X,
//     palms down, thumbs level at 45° between the arm and +Z, legs straight
//     down, feet along +Z; the trunk, neck, head, shoulders and the feet's
//     pitch keep the source's rest shape;
//   - Unity's axes: left-handed, +Y up, +Z forward, the character's left at
//     −X; lengths in metres.
//
// How: the humanoid is a rig built from the source's rest pose (each bone as
// long as the source's, in metres), and common/retarget's Retargeter gives
// the per-role rest alignment A_r and the source → humanoid axes C; a bone's
// world rotation is W = C · W_s · Cᵀ · A_r (docs/retarget.md), its local
// rotation Wᵀ_parent · W, and the axes are mirrored into Unity's (x → −x).
// The humanoid's bone offsets are the source's rest offsets o_s turned into
// its parent's rest frame (A_pᵀ · C · o_s), so forward kinematics on the
// humanoid (the local positions this class gives, the hips' position and
// the local rotations) puts every bone where the source's joint is,
// U · C · p_s (in metres, U = diag(−1, 1, 1)), exactly as long as no source
// joint between two mapped roles turns (SMPL-X has none: every joint on the
// way between roles plays one; CMU's upper neck is one).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/motion/skeleton.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"
#include "common/retarget/roles.h"
#include "common/status/status.h"

namespace kinemo::vmc {

// Bone names: Unity's HumanBodyBones ("Hips", "LeftThumbProximal", the VMC
// protocol's names, what EVMC4U, VMC4UE and the VRM apps read) or VRM 1.0's
// humanoid names ("hips", "leftThumbMetacarpal").
enum class BoneNaming { kUnity, kVrm1 };

// "unity" | "vrm1"; INVALID_ARGUMENT naming `field` otherwise.
StatusOr<BoneNaming> ParseBoneNaming(std::string_view text, std::string_view field);
std::string_view BoneNamingName(BoneNaming naming);

// The humanoid bone name of a role (every role has one).
std::string_view BoneName(retarget::Role role, BoneNaming naming);

struct HumanoidOptions {
  // The source's unit in metres; 0 = estimated from its legs
  // (retarget::EstimateMetersPerUnit: cm for SMPL-X BEAT2 files).
  double meters_per_unit = 0;
  // A JSON role map for a skeleton no built-in family fits (roles.h).
  std::string role_map_json;
  // Send the finger bones (when the source has them).
  bool fingers = true;
};

struct HumanoidBone {
  retarget::Role role;
  int parent;  // index into bones(), -1 for the hips
  // Local position in the parent (Unity axes, metres); the hips' is its rest
  // position above the floor.
  Eigen::Vector3d local_position_m;
  int source_joint;  // the joint of the source skeleton playing the role
};

// One frame of the humanoid: per bone (bones() order) its local rotation,
// and the hips' position (Unity axes, metres).
struct HumanoidPose {
  std::vector<Eigen::Quaterniond> local_rotation;
  Eigen::Vector3d hips_position_m = Eigen::Vector3d::Zero();
};

class HumanoidPoser {
 public:
  // The humanoid of `source` (the skeleton of the frames to come): the
  // roles it has (hips, spine, ... as detected or mapped), fingers when
  // asked. INVALID_ARGUMENT / NOT_FOUND when no role map fits (naming the
  // missing roles).
  static StatusOr<HumanoidPoser> Create(const motion::Skeleton& source, const HumanoidOptions& options = {});

  // Bones in parent-first order (the hips first).
  std::span<const HumanoidBone> bones() const { return bones_; }
  // The source's unit in metres (given or estimated).
  double meters_per_unit() const { return meters_per_unit_; }
  // U · C: a source world direction -> the humanoid's Unity axes (a
  // reflection: det −1). A source position p (file units) is at
  // unity_from_source() · p · meters_per_unit() in the receiver's frame.
  const Eigen::Matrix3d& unity_from_source() const { return unity_from_source_; }

  // The pose of one source frame (source.num_channels() values).
  // Allocation-free once `out` has been sized by a first call.
  Status Pose(std::span<const double> frame, HumanoidPose* out);

 private:
  motion::Skeleton source_;
  std::vector<HumanoidBone> bones_;
  std::vector<Eigen::Matrix3d> align_;  // per bone: A_r (humanoid axes, right-handed)
  Eigen::Matrix3d axes_ = Eigen::Matrix3d::Identity();  // C
  Eigen::Matrix3d unity_from_source_ = Eigen::Matrix3d::Identity();
  double meters_per_unit_ = 1;
  int source_hips_ = -1;
  std::vector<int> needed_;  // source joints whose world pose a frame needs (ascending)
  // Scratch.
  std::vector<Eigen::Vector3d> src_pos_;
  std::vector<Eigen::Matrix3d> src_rot_;
  std::vector<Eigen::Matrix3d> world_;  // per bone
};

}  // namespace kinemo::vmc
