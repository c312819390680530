#include "common/retarget/retarget.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <optional>

#include "common/motion/kinematics.h"
#include "common/retarget/measures.h"

namespace kinemo::retarget {
namespace {

using namespace roles;

// Orthonormal frame from a rig's rest pose: x = right thigh -> left thigh,
// y = hips -> head (made orthogonal), z = x × y.
// Both files are y-up (BVH and glTF are), so the rigs' worlds differ by a
// turn about the vertical only: the frame is +y and the horizontal part of
// the right thigh -> left thigh direction. (A rest pose that is not upright,
// such as Bandai's, and the rigs' different spine curvatures are the
// per-role alignment's business, not a lean of the whole body.)
Eigen::Matrix3d BodyFrame(const RoleMap& map, const std::vector<Eigen::Vector3d>& p) {
  const Eigen::Vector3d y = Eigen::Vector3d::UnitY();
  Eigen::Vector3d x = p[map.joint[Side(0, kThigh)]] - p[map.joint[Side(1, kThigh)]];
  x = x - x.dot(y) * y;
  x = x.norm() > 1e-9 ? Eigen::Vector3d(x.normalized()) : Eigen::Vector3d::UnitX();
  Eigen::Matrix3d f;
  f.col(0) = x;
  f.col(1) = y;
  f.col(2) = x.cross(y);
  return f;
}

// Orthonormal frame with `primary` as its first axis and `secondary`, made
// orthogonal to it, as its second.
Eigen::Matrix3d FrameOf(const Eigen::Vector3d& primary, const Eigen::Vector3d& secondary) {
  Eigen::Matrix3d f;
  f.col(0) = primary.normalized();
  Eigen::Vector3d s = secondary - secondary.dot(f.col(0)) * f.col(0);
  if (s.norm() < 1e-6) s = f.col(0).unitOrthogonal();
  f.col(1) = s.normalized();
  f.col(2) = f.col(0).cross(f.col(1));
  return f;
}

// A role's rest frame in a rig: what it means for the bone to point and turn
// as at rest, in the rig's world axes. The hips are the pelvis (RestAxes);
// the trunk, neck, head and jaw the upper body's axes (a T-pose's chest
// stands and its head looks straight ahead, whatever the spine's curve and
// the neck's lean). Limbs: their direction `bone` (to the next role), turned
// about it by an anatomical axis: thighs and shins by the pelvis' forward,
// feet and toes by its left, shoulders, arms, hands and fingers by the upper
// body's forward (thumbs: its up). None for a limb bone without direction (a
// chain's end: it takes its parent's alignment).
std::optional<Eigen::Matrix3d> RoleRestFrame(Role r, const RestAxes& axes, const std::optional<Eigen::Vector3d>& bone) {
  if (r == kHips) return axes.pelvis;
  if (r < kNumCoreRoles) return axes.upper;
  if (!bone) return std::nullopt;
  const int b = (r - kNumCoreRoles) % kNumSideRoles;
  switch (b) {
    case kThigh:
    case kShin:
      return FrameOf(*bone, axes.pelvis.col(2));
    case kFoot:
    case kToes: {
      // Feet stand on the floor in every rest pose: the bone's heading
      // (its direction with the pelvis' up taken out), not its pitch, so a
      // flat source foot is a flat target foot whatever the two rigs' foot
      // bones slope (SMPL-X's ankle -> ball 24 deg down, the VRM test
      // humanoid's ankle -> toes 45 deg).
      const Eigen::Vector3d up = axes.pelvis.col(1);
      const Eigen::Vector3d heading = *bone - bone->dot(up) * up;
      return FrameOf(heading.norm() > 1e-6 * bone->norm() ? heading : Eigen::Vector3d(axes.pelvis.col(2)),
                     axes.pelvis.col(0));
    }
    default:
      break;
  }
  const bool thumb = b >= kFirstFinger && (b - kFirstFinger) / 3 == 0;
  return FrameOf(*bone, axes.upper.col(thumb ? 1 : 2));
}

}  // namespace

double CharacterSizeScale(const Rig& rig) {
  const double leg_m = rig.LegLength() * rig.meters_per_unit;
  if (!(leg_m > 0) || !std::isfinite(leg_m)) return 1.0;
  return std::clamp(leg_m / 0.7, 0.2, 1.0);
}

motion::FootContactParams ContactParamsFor(const Rig& rig) {
  const double s = CharacterSizeScale(rig);
  motion::FootContactParams c;
  c.meters_per_unit = rig.meters_per_unit;
  c.enter_height_m *= s;
  c.exit_height_m *= s;
  c.enter_speed_m_s *= s;
  c.exit_speed_m_s *= s;
  return c;
}

motion::FootPlantParams PlantParamsFor(const Rig& rig) {
  const double s = CharacterSizeScale(rig);
  motion::FootPlantParams p;
  p.contact = ContactParamsFor(rig);
  p.max_lock_distance_m *= s;
  p.step_height_m *= s;
  return p;
}

StatusOr<Retargeter> Retargeter::Create(const motion::Skeleton& source_skeleton, const Rig& source, const Rig& target,
                                        const RetargetOptions& options) {
  if (source_skeleton.num_joints() != source.skeleton.num_joints()) {
    return absl::InvalidArgumentError("source skeleton and source rig differ");
  }
  if (!(options.frame_time_s > 0) || options.frame_time_s > 1) {
    return InvalidField("frame_time_s", "must be in (0, 1] s, got ", options.frame_time_s);
  }
  KINEMO_RETURN_IF_ERROR(CheckRequiredRoles(source));
  KINEMO_RETURN_IF_ERROR(CheckRequiredRoles(target));
  Retargeter rt;
  rt.source_skeleton_ = source_skeleton;
  rt.target_ = target.skeleton;
  rt.root_motion_ = options.root_motion;
  const std::vector<Eigen::Vector3d> ps = source.RestPositions(), pt = target.RestPositions();
  const RoleMap& sm = source.roles;
  const RoleMap& tm = target.roles;
  rt.axes_ = BodyFrame(tm, pt) * BodyFrame(sm, ps).transpose();

  // The source role each target role follows.
  std::array<int, kNumRoles> src_joint;
  src_joint.fill(-1);
  for (int r = 0; r < kNumRoles; ++r) {
    if (tm.joint[r] < 0) continue;
    if (IsFingerRole(r) && !options.fingers) continue;
    src_joint[r] = sm.joint[r];
  }
  // Trunk: the target's topmost trunk bone follows the source's topmost one;
  // a trunk bone the source lacks follows the next one below.
  auto topmost = [](const RoleMap& m) {
    for (Role r : {kUpperChest, kChest, kSpine}) {
      if (m.joint[r] >= 0) return static_cast<int>(r);
    }
    return -1;
  };
  const int t_top = topmost(tm), s_top = topmost(sm);
  for (Role r : {kSpine, kChest, kUpperChest}) {
    if (tm.joint[r] < 0 || src_joint[r] >= 0) continue;
    for (Role below = r - 1; below >= kSpine; --below) {
      if (sm.joint[below] >= 0) {
        src_joint[r] = sm.joint[below];
        break;
      }
    }
  }
  if (t_top >= 0 && s_top >= 0) src_joint[t_top] = sm.joint[s_top];

  // Per-role rest alignment A_r = F_s · F_tᵀ: F is the role's rest frame in
  // each rig (RoleRestFrame), the source's turned into the target's world.
  const RestAxes as = source.RestBodyAxes(), at = target.RestBodyAxes();
  std::array<Eigen::Matrix3d, kNumRoles> align;
  std::array<bool, kNumRoles> has_align{};
  for (int r = 0; r < kNumRoles; ++r) {
    align[r] = Eigen::Matrix3d::Identity();
    if (src_joint[r] < 0) continue;
    // The bone's direction: towards the next role both rigs have (for the
    // source, the joint that role follows); none at a chain's end.
    std::optional<Eigen::Vector3d> dt, ds;
    for (Role c = ChildRole(r); c >= 0 && !dt; c = ChildRole(c)) {
      if (tm.joint[c] < 0 || src_joint[c] < 0 || src_joint[c] == src_joint[r]) continue;
      const Eigen::Vector3d t = pt[tm.joint[c]] - pt[tm.joint[r]];
      const Eigen::Vector3d v = ps[src_joint[c]] - ps[src_joint[r]];
      if (t.norm() < 1e-9 || v.norm() < 1e-9) continue;
      dt = t;
      ds = v;
    }
    const std::optional<Eigen::Matrix3d> ft = RoleRestFrame(r, at, dt), fs = RoleRestFrame(r, as, ds);
    if (ft && fs) {
      align[r] = rt.axes_ * *fs * ft->transpose();
    } else {
      for (Role p = ParentRole(r); p >= 0; p = ParentRole(p)) {
        if (has_align[p]) {
          align[r] = align[p];
          break;
        }
      }
    }
    has_align[r] = true;
  }
  const int nt = target.skeleton.num_joints();
  rt.source_of_target_.assign(static_cast<size_t>(nt), -1);
  rt.align_.assign(static_cast<size_t>(nt), Eigen::Matrix3d::Identity());
  rt.role_transferred_.assign(kNumRoles, false);
  rt.role_present_.assign(kNumRoles, false);
  for (int r = 0; r < kNumRoles; ++r) {
    rt.role_present_[r] = tm.joint[r] >= 0 || sm.joint[r] >= 0;
    if (src_joint[r] < 0) continue;
    rt.source_of_target_[tm.joint[r]] = src_joint[r];
    rt.align_[tm.joint[r]] = align[r];
    rt.role_transferred_[r] = true;
  }
  // Joints without a role that both skeletons have by name (eyes, twist
  // bones, a Bandai joint_Root) follow too, aligned like their nearest
  // transferred ancestor: onto the same family nothing is left at rest.
  {
    std::vector<bool> source_has_role(static_cast<size_t>(source.skeleton.num_joints()), false);
    for (int r = 0; r < kNumRoles; ++r) {
      if (sm.joint[r] >= 0) source_has_role[sm.joint[r]] = true;
    }
    std::vector<bool> target_has_role(static_cast<size_t>(nt), false);
    for (int r = 0; r < kNumRoles; ++r) {
      if (tm.joint[r] >= 0) target_has_role[tm.joint[r]] = true;
    }
    for (int j = 0; j < nt; ++j) {
      if (target_has_role[j]) continue;
      const int s = source.skeleton.FindJoint(target.skeleton.joint(j).name);
      if (s < 0 || source_has_role[s]) continue;
      rt.source_of_target_[j] = s;
      for (int a = target.skeleton.joint(j).parent; a >= 0; a = target.skeleton.joint(a).parent) {
        if (rt.source_of_target_[a] >= 0) {
          rt.align_[j] = rt.align_[a];
          break;
        }
      }
    }
  }
  const double ls = source.LegLength(), lt = target.LegLength();
  rt.scale_ = ls > 0 && lt > 0 ? lt / ls : target.meters_per_unit == 0 ? 1 : source.meters_per_unit / target.meters_per_unit;
  rt.root_scale_m_ = rt.scale_ * target.meters_per_unit / source.meters_per_unit;
  rt.source_height_ = source.HipsHeight();
  rt.target_height_ = target.HipsHeight();
  rt.source_hips_ = sm.joint[kHips];
  rt.target_hips_ = tm.joint[kHips];
  rt.src_pos_.resize(static_cast<size_t>(source_skeleton.num_joints()));
  rt.src_rot_.resize(rt.src_pos_.size());
  rt.tgt_pos_.resize(static_cast<size_t>(nt));
  rt.tgt_rot_.resize(static_cast<size_t>(nt));
  rt.previous_.assign(static_cast<size_t>(target.skeleton.num_channels()), 0.0);
  rt.options_ = options;
  rt.target_regions_ = RegionsFromRoles(target);
  rt.target_mpu_ = target.meters_per_unit;
  rt.plant_params_ = PlantParamsFor(target);
  rt.frame_time_s_ = options.frame_time_s;
  KINEMO_RETURN_IF_ERROR(rt.MakePlanter(options.frame_time_s));
  return rt;
}

Status Retargeter::MakePlanter(double frame_time_s) {
  planter_.reset();
  if (!options_.plant_feet) return absl::OkStatus();
  auto planter = motion::FootPlanter::Create(target_, target_regions_, frame_time_s, plant_params_);
  if (planter.ok()) {
    planter_ = *std::move(planter);
  } else if (planter.status().code() != absl::StatusCode::kFailedPrecondition) {
    return planter.status();
  }
  return absl::OkStatus();
}

void Retargeter::Reset() {
  has_previous_ = false;
  // A fresh planter (its contacts and locks belong to the previous clip);
  // it was created once with these parameters, so this cannot fail.
  if (planter_) MakePlanter(frame_time_s_).IgnoreError();
}

Status Retargeter::RetargetFrame(std::span<const double> source_frame, std::span<double> target_frame) {
  if (static_cast<int>(target_frame.size()) != target_.num_channels()) {
    return absl::InvalidArgumentError("target frame size differs from the target skeleton's channels");
  }
  KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(source_skeleton_, source_frame, src_pos_, src_rot_));
  const Eigen::Vector3d up(0, 1, 0);
  for (int j = 0; j < target_.num_joints(); ++j) {
    const motion::Joint& joint = target_.joint(j);
    const int parent = joint.parent;
    const Eigen::Matrix3d parent_rot = parent >= 0 ? tgt_rot_[parent] : Eigen::Matrix3d::Identity();
    const Eigen::Vector3d parent_pos = parent >= 0 ? tgt_pos_[parent] : Eigen::Vector3d::Zero();
    const int s = source_of_target_[j];
    tgt_rot_[j] = s >= 0 ? Eigen::Matrix3d(axes_ * src_rot_[s] * axes_.transpose() * align_[j]) : parent_rot;
    if (j == target_hips_ && root_motion_) {
      tgt_pos_[j] = scale_ * (axes_ * (src_pos_[source_hips_] - source_height_ * up)) + target_height_ * up;
    } else {
      tgt_pos_[j] = parent_pos + parent_rot * joint.offset;
    }
    if (joint.has_position_channels()) {
      const Eigen::Vector3d local_t = parent_rot.transpose() * (tgt_pos_[j] - parent_pos);
      for (int a = 0; a < 3; ++a) {
        if (joint.position_column[a] >= 0) target_frame[joint.position_column[a]] = local_t[a];
      }
    }
    if (joint.num_rotations == 3) {
      const Eigen::Matrix3d local = parent_rot.transpose() * tgt_rot_[j];
      Eigen::Vector3d reference = Eigen::Vector3d::Zero();
      if (has_previous_) {
        for (int k = 0; k < 3; ++k) reference[k] = previous_[joint.rotation_column[k]];
      }
      const Eigen::Vector3d angles = motion::MatrixToEuler(local, joint.rotation_axis, reference);
      for (int k = 0; k < 3; ++k) target_frame[joint.rotation_column[k]] = angles[k];
    }
  }
  if (planter_) planter_->Apply(target_frame);
  std::copy(target_frame.begin(), target_frame.end(), previous_.begin());
  has_previous_ = true;
  return absl::OkStatus();
}

StatusOr<motion::Clip> Retargeter::RetargetClip(const motion::Clip& source) {
  KINEMO_RETURN_IF_ERROR(source.Validate());
  if (source.skeleton.num_channels() != source_skeleton_.num_channels()) {
    return absl::InvalidArgumentError("clip is not on the retargeter's source skeleton");
  }
  motion::Clip out;
  out.skeleton = target_;
  out.frame_time_s = source.frame_time_s;
  out.frames.resize(source.num_frames(), target_.num_channels());
  if (frame_time_s_ != source.frame_time_s && planter_) {
    frame_time_s_ = source.frame_time_s;
    KINEMO_RETURN_IF_ERROR(MakePlanter(frame_time_s_));
  }
  frame_time_s_ = source.frame_time_s;
  Reset();
  for (int f = 0; f < source.num_frames(); ++f) {
    std::span<double> row(out.frames.data() + static_cast<Eigen::Index>(f) * out.frames.cols(),
                          static_cast<size_t>(out.frames.cols()));
    KINEMO_RETURN_IF_ERROR(RetargetFrame(source.frame(f), row));
  }
  return out;
}

std::vector<std::string> Retargeter::MappedRoles() const {
  std::vector<std::string> out;
  for (int r = 0; r < kNumRoles; ++r) {
    if (role_transferred_[r]) out.emplace_back(RoleName(r));
  }
  return out;
}

std::vector<std::string> Retargeter::UnmappedRoles() const {
  std::vector<std::string> out;
  for (int r = 0; r < kNumRoles; ++r) {
    if (role_present_[r] && !role_transferred_[r]) out.emplace_back(RoleName(r));
  }
  return out;
}

StatusOr<RetargetResult> RetargetClip(const motion::Clip& source, double source_meters_per_unit, const Rig& target,
                                      const RetargetOptions& options, const RoleMapChoice& source_choice) {
  KINEMO_ASSIGN_OR_RETURN(Rig source_rig, RigFromSkeleton(source.skeleton, source_meters_per_unit, "source", source_choice));
  KINEMO_ASSIGN_OR_RETURN(Retargeter rt, Retargeter::Create(source.skeleton, source_rig, target, options));
  RetargetResult result;
  KINEMO_ASSIGN_OR_RETURN(result.clip, rt.RetargetClip(source));
  result.mapped_roles = rt.MappedRoles();
  result.unmapped_roles = rt.UnmappedRoles();
  result.root_scale = rt.root_scale();
  return result;
}

}  // namespace kinemo::retarget
