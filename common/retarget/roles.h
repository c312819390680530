// Canonical humanoid roles and the bone maps that name them on each skeleton
// family kinemo knows (see docs/retarget.md).
//
// A role is a bone of an idealised humanoid: hips, spine, chest, upper chest,
// neck, head, jaw, and per side shoulder (clavicle), upper arm, forearm,
// hand, thigh, shin, foot, toes and three bones per finger (thumb, index,
// middle, ring, little; 1 = proximal). A RoleMap gives, per role, the joint
// of a skeleton that plays it (or none).
//
// Built-in families (detected from joint names): SMPL-X, Bandai-Namco,
// CMU cgspeed (31 joints), CMU iClone (CC_Base_*), Mixamo (mixamorig:*),
// Quaternius (Hips/Abdomen/Torso/Chest, UpperArm.L, ...). VRM rigs carry
// their own map (the VRM extension's humanBones, read by rig.h). Anything
// else: a JSON object {"role": "joint name", ...} (ParseRoleMapJson).
#pragma once

#include <array>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::retarget {

// Roles are small integers; kNumRoles of them.
using Role = int;
inline constexpr int kNumCoreRoles = 7;   // hips spine chest upper_chest neck head jaw
inline constexpr int kNumSideRoles = 23;  // shoulder..toes (8) + 15 finger bones
inline constexpr int kNumRoles = kNumCoreRoles + 2 * kNumSideRoles;

namespace roles {
inline constexpr Role kHips = 0, kSpine = 1, kChest = 2, kUpperChest = 3, kNeck = 4, kHead = 5, kJaw = 6;
// Per side: side 0 = left, 1 = right.
enum SideBone : int {
  kShoulder = 0,
  kUpperArm,
  kForearm,
  kHand,
  kThigh,
  kShin,
  kFoot,
  kToes,
  kFirstFinger,  // thumb1; finger f (0 thumb .. 4 little), bone b (0..2): kFirstFinger + 3f + b
};
inline constexpr Role Side(int side, int bone) { return kNumCoreRoles + side * kNumSideRoles + bone; }
inline constexpr Role Finger(int side, int finger, int bone) {
  return Side(side, kFirstFinger + 3 * finger + bone);
}
}  // namespace roles

// "hips", "upper_chest", "left_upper_arm", "right_index2", ...
std::string_view RoleName(Role role);
std::optional<Role> ParseRole(std::string_view name);
// The next bone away from the body (upper_arm -> forearm, hand -> middle1,
// hips -> spine, head -> none): -1 at a chain's end.
Role ChildRole(Role role);
// The bone towards the body (forearm -> upper_arm, middle1 -> hand,
// shoulder -> upper_chest): -1 for hips.
Role ParentRole(Role role);
bool IsFingerRole(Role role);

// Roles a rig must have to be driven: hips, head, both upper arms, forearms,
// thighs and shins, and at least one spine bone (spine, chest or upper chest).
std::vector<std::string> MissingRequiredRoles(const std::array<int, kNumRoles>& joints);

enum class RigFamily {
  kCustom,  // a JSON map
  kSmplx,
  kBandai,
  kCmu31,
  kCmuIclone,
  kMixamo,
  kVrm,
  kQuaternius,
};
// "custom", "smplx", "bandai", "cmu31", "cmu_iclone", "mixamo", "vrm", "quaternius".
std::string_view RigFamilyName(RigFamily family);

// Which joint plays each role (-1 = none).
struct RoleMap {
  RigFamily family = RigFamily::kCustom;
  std::array<int, kNumRoles> joint;
  RoleMap() { joint.fill(-1); }
  int num_mapped() const;
};

// A family's bone names: role -> joint name ("" = the family has no such bone).
struct RoleNames {
  RigFamily family;
  std::array<std::string, kNumRoles> names;
};

// The built-in name tables (not VRM, whose maps are per file).
std::span<const RoleNames> BuiltInRoleNames();

// Resolves names to joint indices with `find` (name -> index or -1).
template <typename Find>
RoleMap ResolveRoleNames(const RoleNames& names, Find&& find) {
  RoleMap map;
  map.family = names.family;
  for (int r = 0; r < kNumRoles; ++r) {
    if (!names.names[r].empty()) map.joint[r] = find(names.names[r]);
  }
  return map;
}

// The built-in family whose names match most required roles of the joint
// names (ties: more roles overall); NOT_FOUND naming the best candidate's
// missing roles when none has them all.
StatusOr<RoleMap> DetectRoleMap(std::span<const std::string> joint_names);

// {"hips": "pelvis", "left_upper_arm": "L_UpperArm", ...} (keys are role
// names; values joint names, which must exist). Errors name the key.
StatusOr<RoleNames> ParseRoleMapJson(std::string_view text, std::string_view source_name);

// Joint names -> RoleMap through `names`; INVALID_ARGUMENT naming a mapped
// joint that is not in the skeleton.
StatusOr<RoleMap> ApplyRoleNames(const RoleNames& names, std::span<const std::string> joint_names,
                                 std::string_view source_name);

}  // namespace kinemo::retarget
