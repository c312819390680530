#include "common/retarget/measures.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "common/motion/kinematics.h"

namespace kinemo::retarget {
namespace {

using namespace roles;

motion::BodyRegion RegionOf(Role r) {
  using motion::BodyRegion;
  if (r == kHips || r == kSpine || r == kChest || r == kUpperChest) return BodyRegion::kTrunk;
  if (r == kNeck || r == kHead || r == kJaw) return BodyRegion::kHead;
  const int side = (r - kNumCoreRoles) / kNumSideRoles;
  const int bone = (r - kNumCoreRoles) % kNumSideRoles;
  if (bone <= kForearm) return side == 0 ? BodyRegion::kLeftArm : BodyRegion::kRightArm;
  if (bone == kHand || bone >= kFirstFinger) return side == 0 ? BodyRegion::kLeftHand : BodyRegion::kRightHand;
  return side == 0 ? BodyRegion::kLeftLeg : BodyRegion::kRightLeg;
}

int TopOfTrunk(const RoleMap& m) {
  for (Role r : {kNeck, kUpperChest, kChest, kSpine}) {
    if (m.joint[r] >= 0) return m.joint[r];
  }
  return -1;
}

}  // namespace

motion::BodyRegionMap RegionsFromRoles(const Rig& rig) {
  std::map<std::string, motion::BodyRegion, std::less<>> names;
  for (int r = 0; r < kNumRoles; ++r) {
    if (rig.roles.joint[r] >= 0) names[rig.skeleton.joint(rig.roles.joint[r]).name] = RegionOf(r);
  }
  return motion::MapBodyRegions(rig.skeleton, motion::BodyRegionRules::FromMap(names));
}

StatusOr<HandTorsoCheck> CheckHandsInTorso(const motion::Clip& clip, const Rig& rig, double radius_fraction) {
  if (!(radius_fraction > 0) || radius_fraction > 10) return InvalidField("radius_fraction", "must be in (0, 10]");
  const RoleMap& m = rig.roles;
  const int hips = m.joint[kHips], top = TopOfTrunk(m);
  const int lt = m.joint[Side(0, kThigh)], rt = m.joint[Side(1, kThigh)];
  const int hands[2] = {m.joint[Side(0, kHand)], m.joint[Side(1, kHand)]};
  if (hips < 0 || top < 0 || lt < 0 || rt < 0 || hands[0] < 0 || hands[1] < 0) {
    return absl::FailedPreconditionError("the rig lacks hips, trunk, thighs or hands");
  }
  const std::vector<Eigen::Vector3d> rest = rig.RestPositions();
  const double radius = radius_fraction * (rest[lt] - rest[rt]).norm();
  HandTorsoCheck check;
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(clip.skeleton.num_joints()));
  std::vector<Eigen::Matrix3d> rot(pos.size());
  for (int f = 0; f < clip.num_frames(); ++f) {
    KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(clip.skeleton, clip.frame(f), pos, rot));
    const Eigen::Vector3d a = pos[hips], b = pos[top];
    const Eigen::Vector3d ab = b - a;
    bool inside = false;
    for (int h : hands) {
      const double t = std::clamp((pos[h] - a).dot(ab) / std::max(ab.squaredNorm(), 1e-12), 0.0, 1.0);
      const double d = (pos[h] - (a + t * ab)).norm();
      if (d < radius) {
        inside = true;
        check.deepest_m = std::max(check.deepest_m, (radius - d) * rig.meters_per_unit);
      }
    }
    ++check.frames;
    check.frames_inside += inside ? 1 : 0;
  }
  return check;
}

StatusOr<std::vector<Eigen::Vector3d>> BoneDirections(const motion::Clip& clip, const Rig& rig, Role role) {
  std::vector<Eigen::Vector3d> out;
  const int j = rig.roles.joint[role];
  int c = -1;
  for (Role r = ChildRole(role); r >= 0 && c < 0; r = ChildRole(r)) c = rig.roles.joint[r];
  if (j < 0 || c < 0) return out;
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(clip.skeleton.num_joints()));
  std::vector<Eigen::Matrix3d> rot(pos.size());
  for (int f = 0; f < clip.num_frames(); ++f) {
    KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(clip.skeleton, clip.frame(f), pos, rot));
    out.push_back((pos[c] - pos[j]).normalized());
  }
  return out;
}

}  // namespace kinemo::retarget
