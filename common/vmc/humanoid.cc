#include "common/vmc/humanoid.h"

#include <array>
#include <cmath>

#include "common/motion/kinematics.h"

namespace kinemo::vmc {
namespace {

using retarget::Role;
using namespace retarget::roles;

// The names of the roles, spelled from their parts (roles.h order).
struct Spelling {
  std::array<std::string_view, retarget::kNumCoreRoles> core;
  std::array<std::string_view, 2> side;
  std::array<std::string_view, 8> limb;
  std::array<std::string_view, 5> finger;
  std::array<std::string_view, 3> phalanx;
  std::array<std::string_view, 3> thumb;
};

constexpr Spelling kUnitySpelling = {
    {"Hips", "Spine", "Chest", "UpperChest", "Neck", "Head", "Jaw"},
    {"Left", "Right"},
    {"Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"},
    {"Thumb", "Index", "Middle", "Ring", "Little"},
    {"Proximal", "Intermediate", "Distal"},
    {"Proximal", "Intermediate", "Distal"},
};
constexpr Spelling kVrm1Spelling = {
    {"hips", "spine", "chest", "upperChest", "neck", "head", "jaw"},
    {"left", "right"},
    {"Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"},
    {"Thumb", "Index", "Middle", "Ring", "Little"},
    {"Proximal", "Intermediate", "Distal"},
    {"Metacarpal", "Proximal", "Distal"},
};

std::array<std::string, retarget::kNumRoles> Spell(const Spelling& sp) {
  std::array<std::string, retarget::kNumRoles> names;
  for (int r = 0; r < retarget::kNumCoreRoles; ++r) names[r] = std::string(sp.core[r]);
  for (int side = 0; side < 2; ++side) {
    for (int b = 0; b < 8; ++b) names[Side(side, b)] = kinemo::StrCat(sp.side[side], sp.limb[b]);
    for (int f = 0; f < 5; ++f) {
      for (int b = 0; b < 3; ++b) {
        names[Finger(side, f, b)] = kinemo::StrCat(sp.side[side], sp.finger[f], f == 0 ? sp.thumb[b] : sp.phalanx[b]);
      }
    }
  }
  return names;
}

const std::array<std::string, retarget::kNumRoles>& Names(BoneNaming naming) {
  static const auto* unity = new std::array<std::string, retarget::kNumRoles>(Spell(kUnitySpelling));
  static const auto* vrm1 = new std::array<std::string, retarget::kNumRoles>(Spell(kVrm1Spelling));
  return naming == BoneNaming::kUnity ? *unity : *vrm1;
}

int SideOf(Role r) { return (r - retarget::kNumCoreRoles) / retarget::kNumSideRoles; }
int BoneOf(Role r) { return (r - retarget::kNumCoreRoles) % retarget::kNumSideRoles; }

// How a role's bone points in the VRM T-pose, in the humanoid's own
// right-handed axes (x = the character's left, y up, z forward), given its
// direction in the source's rest expressed in those axes (`own`). Arms, hands
// and fingers along the arm (left +x), thumbs level at 45° forward, thighs
// and shins straight down, feet straight forward with the source's pitch;
// the others keep their own direction.
Eigen::Vector3d TPoseDirection(Role r, const Eigen::Vector3d& own) {
  if (r < retarget::kNumCoreRoles) return own;
  const double out = SideOf(r) == 0 ? 1.0 : -1.0;
  const int b = BoneOf(r);
  if (b >= kFirstFinger) {
    return (b - kFirstFinger) / 3 == 0 ? Eigen::Vector3d(out, 0, 1).normalized() : Eigen::Vector3d(out, 0, 0);
  }
  switch (b) {
    case kUpperArm:
    case kForearm:
    case kHand:
      return {out, 0, 0};
    case kThigh:
    case kShin:
      return {0, -1, 0};
    case kFoot: {
      const Eigen::Vector3d sagittal(0, own.y(), own.z());
      return sagittal.norm() > 1e-9 ? Eigen::Vector3d(sagittal.normalized()) : own;
    }
    default:
      return own;
  }
}

}  // namespace

StatusOr<BoneNaming> ParseBoneNaming(std::string_view text, std::string_view field) {
  if (text == "unity") return BoneNaming::kUnity;
  if (text == "vrm1") return BoneNaming::kVrm1;
  return InvalidField(field, "'", text, "' is not unity or vrm1");
}

std::string_view BoneNamingName(BoneNaming naming) { return naming == BoneNaming::kUnity ? "unity" : "vrm1"; }

std::string_view BoneName(Role role, BoneNaming naming) {
  if (role < 0 || role >= retarget::kNumRoles) return "";
  return Names(naming)[role];
}

StatusOr<HumanoidPoser> HumanoidPoser::Create(const motion::Skeleton& source, const HumanoidOptions& options) {
  if (!(options.meters_per_unit >= 0) || !std::isfinite(options.meters_per_unit) || options.meters_per_unit > 1000) {
    return InvalidField("meters_per_unit", "must be in [0, 1000] (0 = estimated), got ", options.meters_per_unit);
  }
  retarget::RoleMapChoice choice;
  choice.map_json = options.role_map_json;
  choice.map_source = "role map";
  const double given = options.meters_per_unit;
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig src, retarget::RigFromSkeleton(source, given > 0 ? given : 1.0, "source", choice));
  if (!(given > 0)) src.meters_per_unit = retarget::EstimateMetersPerUnit(src);
  const double mpu = src.meters_per_unit;
  const std::vector<Eigen::Vector3d> rest = src.RestPositions();
  const retarget::RestAxes axes = src.RestBodyAxes();

  HumanoidPoser h;
  h.source_ = source;
  h.meters_per_unit_ = mpu;
  // The bones: every role the source plays (fingers when asked), in role
  // order, which puts parents first; each one's parent is the nearest
  // humanoid ancestor it has.
  std::array<int, retarget::kNumRoles> bone_of;
  bone_of.fill(-1);
  for (Role r = 0; r < retarget::kNumRoles; ++r) {
    if (src.roles.joint[r] < 0 || (retarget::IsFingerRole(r) && !options.fingers)) continue;
    int parent = -1;
    for (Role p = retarget::ParentRole(r); p >= 0 && parent < 0; p = retarget::ParentRole(p)) parent = bone_of[p];
    if (r != kHips && parent < 0) continue;  // (the hips are required: every other role has them above)
    bone_of[r] = static_cast<int>(h.bones_.size());
    h.bones_.push_back({r, parent, Eigen::Vector3d::Zero(), src.roles.joint[r]});
  }
  const int n = static_cast<int>(h.bones_.size());
  // The bone (index) each one's rest direction is taken towards: the next
  // role along its chain that the humanoid has (as the Retargeter does).
  std::vector<int> towards(static_cast<size_t>(n), -1);
  for (int i = 0; i < n; ++i) {
    const Role r = h.bones_[i].role;
    for (Role c = retarget::ChildRole(r); c >= 0; c = retarget::ChildRole(c)) {
      const int k = bone_of[c];
      if (k < 0 || (rest[h.bones_[k].source_joint] - rest[h.bones_[i].source_joint]).norm() < 1e-9) continue;
      towards[i] = k;
      break;
    }
  }
  // Offsets in the humanoid's right-handed axes (metres): the source's rest
  // offset expressed in the axes of its parent's body part (the pelvis for
  // the hips' and the legs' children, the upper body otherwise: both map to
  // the humanoid's x left, y up, z forward), the T-pose direction for a
  // limb's next bone.
  auto rest_offset = [&](int i) -> Eigen::Vector3d {
    const HumanoidBone& b = h.bones_[i];
    const HumanoidBone& p = h.bones_[b.parent];
    const bool leg = p.role >= retarget::kNumCoreRoles && BoneOf(p.role) >= kThigh && BoneOf(p.role) <= kToes;
    const Eigen::Matrix3d& frame = p.role == kHips || leg ? axes.pelvis : axes.upper;
    return frame.transpose() * (rest[b.source_joint] - rest[p.source_joint]) * mpu;
  };
  std::vector<Eigen::Vector3d> offset(static_cast<size_t>(n), Eigen::Vector3d::Zero());
  for (int i = 1; i < n; ++i) {
    offset[i] = rest_offset(i);
    const int p = h.bones_[i].parent;
    if (towards[p] == i) offset[i] = offset[i].norm() * TPoseDirection(h.bones_[p].role, offset[i].normalized());
  }
  auto make_rig = [&](const std::vector<Eigen::Vector3d>& off) -> StatusOr<retarget::Rig> {
    std::vector<motion::Joint> joints(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
      motion::Joint& j = joints[i];
      j.name = std::string(retarget::RoleName(h.bones_[i].role));
      j.parent = h.bones_[i].parent;
      j.offset = i == 0 ? Eigen::Vector3d(0, axes.pelvis.col(1).dot(rest[h.bones_[0].source_joint]) * mpu, 0) : off[i];
      if (i == 0) {
        j.channels = {motion::ChannelType::kXPosition, motion::ChannelType::kYPosition,
                      motion::ChannelType::kZPosition};
      }
      j.channels.insert(j.channels.end(), {motion::ChannelType::kZRotation, motion::ChannelType::kXRotation,
                                           motion::ChannelType::kYRotation});
    }
    retarget::Rig rig;
    rig.name = "vmc-humanoid";
    KINEMO_ASSIGN_OR_RETURN(rig.skeleton, motion::Skeleton::Create(std::move(joints)));
    rig.meters_per_unit = 1;
    for (int i = 0; i < n; ++i) rig.roles.joint[h.bones_[i].role] = i;
    rig.bind_rotation.assign(static_cast<size_t>(n), Eigen::Matrix3d::Identity());
    rig.node.assign(static_cast<size_t>(n), -1);
    return rig;
  };
  retarget::RetargetOptions ro;
  ro.fingers = options.fingers;
  ro.root_motion = false;
  ro.plant_feet = false;
  // Pass 1: the alignments, which depend only on the body axes and on each
  // limb's direction towards its next bone (both final already).
  KINEMO_ASSIGN_OR_RETURN(retarget::Rig first, make_rig(offset));
  KINEMO_ASSIGN_OR_RETURN(retarget::Retargeter rt, retarget::Retargeter::Create(source, src, first, ro));
  h.axes_ = rt.world_axes();
  h.align_.resize(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) h.align_[i] = rt.alignment(i);
  // Pass 2: every offset becomes A_pᵀ · C · o_s, which makes forward
  // kinematics on the humanoid follow the source exactly (the next bones of
  // limbs and the trunk are unchanged by it; a hand's other fingers, a
  // foot's other bones move into the T-pose with their parent).
  for (int i = 1; i < n; ++i) {
    const HumanoidBone& b = h.bones_[i];
    const Eigen::Vector3d o = (rest[b.source_joint] - rest[h.bones_[b.parent].source_joint]) * mpu;
    offset[i] = h.align_[b.parent].transpose() * h.axes_ * o;
  }
  const Eigen::Matrix3d mirror = Eigen::Vector3d(-1, 1, 1).asDiagonal();
  h.unity_from_source_ = mirror * h.axes_;
  h.bones_[0].local_position_m = h.unity_from_source_ * rest[h.bones_[0].source_joint] * mpu;
  for (int i = 1; i < n; ++i) h.bones_[i].local_position_m = mirror * offset[i];
  h.source_hips_ = h.bones_[0].source_joint;
  std::vector<int> wanted;
  for (const HumanoidBone& b : h.bones_) wanted.push_back(b.source_joint);
  h.needed_ = motion::JointsWithAncestors(source, wanted);
  h.src_pos_.assign(static_cast<size_t>(source.num_joints()), Eigen::Vector3d::Zero());
  h.src_rot_.assign(static_cast<size_t>(source.num_joints()), Eigen::Matrix3d::Identity());
  h.world_.assign(static_cast<size_t>(n), Eigen::Matrix3d::Identity());
  return h;
}

Status HumanoidPoser::Pose(std::span<const double> frame, HumanoidPose* out) {
  if (static_cast<int>(frame.size()) != source_.num_channels()) {
    return InvalidField("frame", frame.size(), " values, the skeleton has ", source_.num_channels(), " channels");
  }
  KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPoseOf(source_, frame, needed_, src_pos_, src_rot_));
  const size_t n = bones_.size();
  out->local_rotation.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const HumanoidBone& b = bones_[i];
    world_[i] = axes_ * src_rot_[b.source_joint] * axes_.transpose() * align_[i];
    const Eigen::Matrix3d local = b.parent < 0 ? world_[i] : Eigen::Matrix3d(world_[b.parent].transpose() * world_[i]);
    // Mirrored into Unity's axes (x -> -x): U · R · U, whose quaternion is
    // (w, x, -y, -z) of R's.
    const Eigen::Quaterniond q(local);
    out->local_rotation[i] = Eigen::Quaterniond(q.w(), q.x(), -q.y(), -q.z()).normalized();
  }
  out->hips_position_m = unity_from_source_ * src_pos_[source_hips_] * meters_per_unit_;
  return absl::OkStatus();
}

}  // namespace kinemo::vmc
