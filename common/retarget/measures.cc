#include "common/retarget/measures.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "common/motion/kinematics.h"
#include "common/motion/motion_check.h"

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

const char* FacingPartName(int part) {
  static const char* const kNames[kNumFacingParts] = {"hips", "chest", "neck", "head"};
  return part >= 0 && part < kNumFacingParts ? kNames[part] : "none";
}

StatusOr<std::vector<Facing>> Facings(const motion::Clip& clip, const Rig& rig) {
  if (clip.skeleton.num_joints() != rig.skeleton.num_joints()) {
    return absl::InvalidArgumentError("clip is not on the rig's skeleton");
  }
  const RoleMap& m = rig.roles;
  int chest = -1;
  for (Role r : {kUpperChest, kChest, kSpine}) {
    if (chest < 0) chest = m.joint[r];
  }
  const int hips = m.joint[kHips], head = m.joint[kHead];
  const int neck = m.joint[kNeck] >= 0 ? m.joint[kNeck] : chest;
  const int thighs[2] = {m.joint[Side(0, kThigh)], m.joint[Side(1, kThigh)]};
  const int arms[2] = {m.joint[Side(0, kUpperArm)], m.joint[Side(1, kUpperArm)]};
  if (hips < 0 || chest < 0 || head < 0 || thighs[0] < 0 || thighs[1] < 0 || arms[0] < 0 || arms[1] < 0) {
    return absl::FailedPreconditionError("the rig lacks hips, trunk, head, thighs or upper arms");
  }
  const RestAxes axes = rig.RestBodyAxes();
  const int joint[kNumFacingParts] = {hips, chest, neck, head};
  std::vector<Facing> out;
  out.reserve(static_cast<size_t>(clip.num_frames()));
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(clip.skeleton.num_joints()));
  std::vector<Eigen::Matrix3d> rot(pos.size());
  for (int f = 0; f < clip.num_frames(); ++f) {
    KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(clip.skeleton, clip.frame(f), pos, rot));
    Facing facing;
    for (int part = 0; part < kNumFacingParts; ++part) {
      const Eigen::Matrix3d& rest = part == kFacingHips ? axes.pelvis : axes.upper;
      facing.up[part] = rot[joint[part]] * rest.col(1);
      facing.forward[part] = rot[joint[part]] * rest.col(2);
    }
    facing.pelvis_left = (pos[thighs[0]] - pos[thighs[1]]).normalized();
    facing.shoulder_left = (pos[arms[0]] - pos[arms[1]]).normalized();
    facing.neck_to_head = (pos[head] - pos[neck]).normalized();
    out.push_back(facing);
  }
  return out;
}

double FacingErrors::worst_p95_deg() const {
  double worst = std::max({pelvis_left_p95_deg, shoulder_left_p95_deg, neck_to_head_p95_deg});
  for (int part = 0; part < kNumFacingParts; ++part) {
    worst = std::max({worst, up_p95_deg[part], forward_p95_deg[part]});
  }
  return worst;
}

StatusOr<FacingErrors> CompareFacings(const motion::Clip& source, const Rig& source_rig, const motion::Clip& target,
                                      const Rig& target_rig, const Eigen::Matrix3d& source_to_target) {
  if (source.num_frames() != target.num_frames()) {
    return absl::InvalidArgumentError("source and target clips differ in frame count");
  }
  KINEMO_ASSIGN_OR_RETURN(std::vector<Facing> a, Facings(source, source_rig));
  KINEMO_ASSIGN_OR_RETURN(std::vector<Facing> b, Facings(target, target_rig));
  auto p95 = [&](auto&& member) {
    std::vector<double> deg;
    deg.reserve(a.size());
    for (size_t f = 0; f < a.size(); ++f) {
      const Eigen::Vector3d u = source_to_target * member(a[f]), v = member(b[f]);
      deg.push_back(std::acos(std::clamp(u.dot(v), -1.0, 1.0)) * 180.0 / M_PI);
    }
    return deg.empty() ? 0.0 : motion::Quantile(deg, 0.95);
  };
  FacingErrors e;
  for (int part = 0; part < kNumFacingParts; ++part) {
    e.up_p95_deg[part] = p95([part](const Facing& x) { return x.up[part]; });
    e.forward_p95_deg[part] = p95([part](const Facing& x) { return x.forward[part]; });
  }
  e.pelvis_left_p95_deg = p95([](const Facing& x) { return x.pelvis_left; });
  e.shoulder_left_p95_deg = p95([](const Facing& x) { return x.shoulder_left; });
  e.neck_to_head_p95_deg = p95([](const Facing& x) { return x.neck_to_head; });
  return e;
}

}  // namespace kinemo::retarget
