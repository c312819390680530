// A rig to retarget from or onto: a skeleton in its rest pose plus the role
// map that names its bones.
//
// Internally every rig is a motion::Skeleton in the "world-aligned rest"
// convention of BVH: the rest pose has identity rotations and the OFFSETs are
// the differences of the joints' rest positions in world axes. For a glTF
// skin the rest pose is the bind pose, each joint's world transform being the
// inverse of its inverseBindMatrix (the pose the mesh was skinned in; the
// node default pose can differ, e.g. robot_expressive.glb has its arms down
// there and a T-pose in its bind matrices). `bind_rotation` keeps each
// joint's bind world orientation so that the node rotations of an animation
// can be rebuilt (gltf.h).
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "common/motion/skeleton.h"
#include "common/retarget/roles.h"
#include "common/status/status.h"

namespace kinemo::retarget {

struct GltfSource;  // the parsed glTF document a rig came from (gltf.h)

// The anatomical axes of a rig's rest pose, in world axes: columns left (the
// character's left), up (head-wards) and forward (the way it faces, left ×
// up). The pelvis takes its left from the thighs, the upper body (trunk above
// the hips, neck, head, arms) from the upper arms. Up is the world's +y when
// the rest pose stands (hips -> head within 45° of vertical: SMPL-X,
// glTF characters, CMU), else the hips -> neck direction: Bandai's zero pose
// lies along +x with the pelvis (left -y) and the chest (left +z) turned 90°
// to each other, so only these axes, not the world's, say which way each
// part faces. Left is made orthogonal to up.
struct RestAxes {
  Eigen::Matrix3d pelvis = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d upper = Eigen::Matrix3d::Identity();
};

struct Rig {
  std::string name;
  // Rest skeleton (see above). The topmost joint and the hips have position
  // channels; every joint has Z X Y rotation channels.
  motion::Skeleton skeleton;
  double meters_per_unit = 1;
  RoleMap roles;
  // Per joint: the bind world rotation of the source node (identity for a
  // BVH skeleton) and the glTF node index (-1 for a BVH skeleton).
  std::vector<Eigen::Matrix3d> bind_rotation;
  std::vector<int> node;
  std::shared_ptr<const GltfSource> gltf;  // null for a BVH skeleton

  // Rest world positions (file units), from the skeleton's offsets.
  std::vector<Eigen::Vector3d> RestPositions() const;
  // Hip-knee-ankle length averaged over both legs (units), 0 without legs.
  double LegLength() const;
  // Height of the hips above the lowest foot point of the rest pose, or
  // above y = 0 when that is lower (units); 1.1 × LegLength() when the rest
  // pose does not stand upright.
  double HipsHeight() const;
  // Role names that are not mapped.
  std::vector<std::string> UnmappedRoles() const;
  // Anatomical axes of the rest pose, see RestAxes.
  RestAxes RestBodyAxes() const;
};


// How the role map is chosen.
struct RoleMapChoice {
  // Non-empty: a JSON map {"role": "joint"} (its text) overrides detection.
  std::string map_json;
  std::string map_source = "map";  // names it in errors
};

// The rig of a BVH skeleton (its own rest pose): the skeleton is rebuilt with
// Z X Y rotation channels on every joint so that clips on it can be written
// back as BVH. `meters_per_unit` is the file's scale (0.01 for centimetres).
StatusOr<Rig> RigFromSkeleton(const motion::Skeleton& skeleton, double meters_per_unit, std::string name,
                              const RoleMapChoice& choice = {});

// Reads a .glb / .gltf (VRM 0.x and 1.0 included): the first skin's joints.
// The role map: the VRM humanoid when present, else --map, else detection.
// Errors: NOT_FOUND for a missing file, INVALID_ARGUMENT for a malformed file,
// no skin, or missing required roles (named).
StatusOr<Rig> LoadGltfRig(const std::string& path, const RoleMapChoice& choice = {});
// The same for a parsed document (ReadGltf, ReadGlbFromMemory); errors name
// src->path.
StatusOr<Rig> RigFromGltf(std::shared_ptr<const GltfSource> src, const RoleMapChoice& choice = {});

// A BVH file's unit from its legs (hip to ankle about 0.8 m for an adult):
// the nearest of 1 (m), 0.1, 0.0254 (inches), 0.01 (cm), 0.001 (mm).
double EstimateMetersPerUnit(const Rig& rig);

// The roles a rig's skeleton plays, checked: INVALID_ARGUMENT naming the
// missing required roles.
Status CheckRequiredRoles(const Rig& rig);

}  // namespace kinemo::retarget
