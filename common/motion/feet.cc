#include "common/motion/feet.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <unordered_set>

#include "common/motion/kinematics.h"

namespace kinemo::motion {
namespace {

// How far a pointed foot's toes may turn up (about 34°).
constexpr double kMaxToesUpRad = 0.6;

// A free foot counts as held on the floor by the lowered body when its sole
// is drawn within this height of the floor and the animation moves it slower
// than this speed (then it stays where it is drawn: see Apply, step 3).
constexpr double kFlooredHeightM = 0.01;
constexpr double kFlooredStillMPerS = 0.05;

// Share of a leg's length (hip-knee plus knee-ankle) a planted target is kept
// within: a straight leg, the knee just off its limit.
constexpr double kReach = 0.9995;

double SmoothStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3 - 2 * x);
}

double HorizontalDistance(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::hypot(a.x() - b.x(), a.z() - b.z());
}

// Soft reach: within `soft` of the leg's `length`, the hip-target distance d
// is eased to L − s·e^{−(d − (L − s))/s} by raising the target (horizontally
// it stays, so a locked foot does not slide); along the hip-target line when
// raising cannot get there.
Eigen::Vector3d EaseNearFullReach(const Eigen::Vector3d& hip, const Eigen::Vector3d& target, double length,
                                  double soft) {
  const Eigen::Vector3d to = target - hip;
  const double d = to.norm(), start = length - soft;
  if (!(soft > 0) || d <= start || d <= 1e-9) return target;
  const double want = start + soft * (1 - std::exp(-(d - start) / soft));
  const double across2 = to.x() * to.x() + to.z() * to.z();
  if (want * want <= across2) return hip + to * (want / d);
  Eigen::Vector3d eased = target;
  eased.y() = hip.y() + std::copysign(std::sqrt(want * want - across2), to.y());
  return eased;
}

// The largest joint index a rig refers to.
int MaxRigJoint(const FeetRig& rig) {
  int m = std::max(rig.pelvis, rig.root);
  for (const LegJoints& leg : rig.legs) {
    m = std::max({m, leg.hip, leg.knee, leg.ankle, leg.toe});
    for (const SolePoint& s : leg.sole) m = std::max(m, s.joint);
  }
  return m;
}

bool IsAncestor(const Skeleton& sk, int ancestor, int j) {
  for (int p = j; p >= 0; p = sk.joint(p).parent) {
    if (p == ancestor) return true;
  }
  return false;
}

Status CheckFinitePositive(std::string_view field, std::string_view name, double v, bool allow_zero) {
  if (!std::isfinite(v) || v < 0 || (!allow_zero && v == 0)) {
    return InvalidField(kinemo::StrCat(field, ".", name), v, allow_zero ? " must be >= 0" : " must be > 0");
  }
  return absl::OkStatus();
}

// The toe direction of a foot (toe joint, else the ankle's End Site), world.
Eigen::Vector3d ToeDirection(const Skeleton& sk, const LegJoints& leg, std::span<const Eigen::Vector3d> pos,
                             std::span<const Eigen::Matrix3d> rot) {
  const size_t a = static_cast<size_t>(leg.ankle);
  if (leg.toe >= 0) return pos[static_cast<size_t>(leg.toe)] - pos[a];
  const Joint& ankle = sk.joint(leg.ankle);
  if (ankle.end_site) return rot[a] * *ankle.end_site;
  return Eigen::Vector3d::Zero();
}

}  // namespace

StatusOr<FeetRig> FeetRig::Find(const Skeleton& sk, const BodyRegionMap& regions) {
  StatusOr<KeyJoints> key = FindKeyJoints(sk, regions);
  if (!key.ok()) return absl::FailedPreconditionError(key.status().message());
  FeetRig rig;
  const std::array<int, 2> ankles = {key->left_foot, key->right_foot};
  const std::array<int, 2> toes = {key->left_toe, key->right_toe};
  for (size_t i = 0; i < 2; ++i) {
    LegJoints& leg = rig.legs[i];
    leg.ankle = ankles[i];
    leg.toe = toes[i];
    leg.knee = sk.joint(leg.ankle).parent;
    leg.hip = leg.knee >= 0 ? sk.joint(leg.knee).parent : -1;
    if (leg.hip < 0 || sk.joint(leg.hip).parent < 0) {
      return absl::FailedPreconditionError(kinemo::StrCat(
          "skeleton: foot joint '", sk.joint(leg.ankle).name, "' has no knee and hip joints above it"));
    }
    for (int j = leg.ankle; j < sk.num_joints(); ++j) {
      if (!IsAncestor(sk, leg.ankle, j)) continue;
      leg.sole.push_back({j, Eigen::Vector3d::Zero()});
      if (sk.joint(j).end_site) leg.sole.push_back({j, *sk.joint(j).end_site});
    }
  }
  std::unordered_set<int> left_up;
  for (int p = sk.joint(rig.legs[0].hip).parent; p >= 0; p = sk.joint(p).parent) left_up.insert(p);
  for (int p = sk.joint(rig.legs[1].hip).parent; p >= 0; p = sk.joint(p).parent) {
    if (left_up.count(p) > 0) {
      rig.pelvis = p;
      break;
    }
  }
  if (rig.pelvis < 0) return absl::FailedPreconditionError("skeleton: the two legs share no ancestor joint");
  rig.root = rig.pelvis;
  while (sk.joint(rig.root).parent >= 0) rig.root = sk.joint(rig.root).parent;
  return rig;
}

Status ValidateFootContactParams(const FootContactParams& p, std::string_view field) {
  KINEMO_RETURN_IF_ERROR(CheckFinitePositive(field, "meters_per_unit", p.meters_per_unit, false));
  if (!std::isfinite(p.ground_height_m)) return InvalidField(kinemo::StrCat(field, ".ground_height_m"), "must be finite");
  KINEMO_RETURN_IF_ERROR(CheckFinitePositive(field, "enter_height_m", p.enter_height_m, true));
  KINEMO_RETURN_IF_ERROR(CheckFinitePositive(field, "enter_speed_m_s", p.enter_speed_m_s, true));
  KINEMO_RETURN_IF_ERROR(CheckFinitePositive(field, "enter_debounce_s", p.enter_debounce_s, true));
  KINEMO_RETURN_IF_ERROR(CheckFinitePositive(field, "exit_debounce_s", p.exit_debounce_s, true));
  if (!std::isfinite(p.exit_height_m) || p.exit_height_m < p.enter_height_m) {
    return InvalidField(kinemo::StrCat(field, ".exit_height_m"), p.exit_height_m, " must be >= enter_height_m");
  }
  if (!std::isfinite(p.exit_speed_m_s) || p.exit_speed_m_s < p.enter_speed_m_s) {
    return InvalidField(kinemo::StrCat(field, ".exit_speed_m_s"), p.exit_speed_m_s, " must be >= enter_speed_m_s");
  }
  if (p.enter_debounce_s > 10 || p.exit_debounce_s > 10) {
    return InvalidField(kinemo::StrCat(field, ".enter_debounce_s/exit_debounce_s"), "must be <= 10 s");
  }
  return absl::OkStatus();
}

FootContactDetector::FootContactDetector(const FootContactParams& params, double frame_time_s) : p_(params) {
  const double dt = frame_time_s > 0 ? frame_time_s : 1.0 / 30;
  enter_frames_ = std::max(1, static_cast<int>(std::lround(p_.enter_debounce_s / dt)));
  exit_frames_ = std::max(1, static_cast<int>(std::lround(p_.exit_debounce_s / dt)));
}

bool FootContactDetector::Update(double sole_height_m, double speed_m_s) {
  if (!started_) {
    started_ = true;
    contact_ = sole_height_m <= p_.enter_height_m;
    last_run_ = 1;
    return contact_;
  }
  const bool change = contact_ ? (sole_height_m > p_.exit_height_m || speed_m_s > p_.exit_speed_m_s)
                               : (sole_height_m <= p_.enter_height_m && speed_m_s <= p_.enter_speed_m_s);
  run_ = change ? run_ + 1 : 0;
  if (run_ >= (contact_ ? exit_frames_ : enter_frames_)) {
    contact_ = !contact_;
    last_run_ = run_;
    run_ = 0;
  }
  return contact_;
}

std::array<double, 2> SoleHeights(const FeetRig& rig, std::span<const Eigen::Vector3d> pos,
                                  std::span<const Eigen::Matrix3d> rot) {
  std::array<double, 2> out{};
  for (size_t i = 0; i < 2; ++i) {
    double lowest = INFINITY;
    for (const SolePoint& s : rig.legs[i].sole) {
      const size_t j = static_cast<size_t>(s.joint);
      lowest = std::min(lowest, pos[j].y() + (rot[j] * s.local).y());
    }
    out[i] = lowest;
  }
  return out;
}

StatusOr<double> EstimateGroundHeight(std::span<const Clip* const> clips, const FeetRig& rig, double meters_per_unit,
                                      int max_frames) {
  int64_t total = 0;
  for (size_t i = 0; i < clips.size(); ++i) {
    if (clips[i]->skeleton.num_joints() <= MaxRigJoint(rig)) {
      return InvalidField(kinemo::StrCat("clips[", i, "]"), "has ", clips[i]->skeleton.num_joints(),
                          " joints, not the rig's skeleton");
    }
    total += clips[i]->num_frames();
  }
  if (total == 0) return 0.0;
  const int64_t stride = std::max<int64_t>(1, (total + std::max(1, max_frames) - 1) / std::max(1, max_frames));
  std::vector<double> heights;
  std::vector<Eigen::Vector3d> pos;
  std::vector<Eigen::Matrix3d> rot;
  int64_t k = 0;
  for (const Clip* c : clips) {
    pos.resize(static_cast<size_t>(c->skeleton.num_joints()));
    rot.resize(pos.size());
    for (int f = 0; f < c->num_frames(); ++f, ++k) {
      if (k % stride != 0) continue;
      KINEMO_RETURN_IF_ERROR(ComputeWorldPose(c->skeleton, c->frame(f), pos, rot));
      for (double h : SoleHeights(rig, pos, rot)) heights.push_back(h * meters_per_unit);
    }
  }
  const size_t q = static_cast<size_t>(0.05 * static_cast<double>(heights.size() - 1) + 0.5);
  std::nth_element(heights.begin(), heights.begin() + static_cast<std::ptrdiff_t>(q), heights.end());
  return heights[q];
}

StatusOr<FeetTrack> AnalyzeFeet(const Clip& clip, const FeetRig& rig, const FootContactParams& params) {
  KINEMO_RETURN_IF_ERROR(ValidateFootContactParams(params));
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  if (clip.skeleton.num_joints() <= MaxRigJoint(rig)) return InvalidField("clip", "not the rig's skeleton");
  const int n = clip.num_frames();
  const double mpu = params.meters_per_unit;
  FeetTrack t;
  t.num_frames = n;
  t.frame_time_s = clip.frame_time_s;
  t.ground_height_m = params.ground_height_m;
  t.pelvis_xz_m.resize(static_cast<size_t>(n));
  for (size_t i = 0; i < 2; ++i) {
    for (auto* v : {&t.sole_height_m[i], &t.ankle_speed_m_s[i], &t.toe_speed_m_s[i], &t.slide_m_s[i]}) {
      v->assign(static_cast<size_t>(n), 0.0);
    }
    t.contact[i].assign(static_cast<size_t>(n), 0);
  }
  std::array<FootContactDetector, 2> detectors = {FootContactDetector(params, clip.frame_time_s),
                                                  FootContactDetector(params, clip.frame_time_s)};
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(clip.skeleton.num_joints()));
  std::vector<Eigen::Matrix3d> rot(pos.size());
  std::array<Eigen::Vector3d, 2> prev_ankle, prev_toe;
  for (int f = 0; f < n; ++f) {
    const size_t uf = static_cast<size_t>(f);
    KINEMO_RETURN_IF_ERROR(ComputeWorldPose(clip.skeleton, clip.frame(f), pos, rot));
    const std::array<double, 2> sole = SoleHeights(rig, pos, rot);
    const Eigen::Vector3d& pelvis = pos[static_cast<size_t>(rig.pelvis)];
    t.pelvis_xz_m[uf] = Eigen::Vector2d(pelvis.x(), pelvis.z()) * mpu;
    for (size_t i = 0; i < 2; ++i) {
      const LegJoints& leg = rig.legs[i];
      const Eigen::Vector3d& ankle = pos[static_cast<size_t>(leg.ankle)];
      const Eigen::Vector3d& toe = leg.toe >= 0 ? pos[static_cast<size_t>(leg.toe)] : ankle;
      t.sole_height_m[i][uf] = sole[i] * mpu;
      if (f > 0) {
        t.ankle_speed_m_s[i][uf] = HorizontalDistance(ankle, prev_ankle[i]) * mpu / clip.frame_time_s;
        t.toe_speed_m_s[i][uf] = HorizontalDistance(toe, prev_toe[i]) * mpu / clip.frame_time_s;
        t.slide_m_s[i][uf] = std::min(t.ankle_speed_m_s[i][uf], t.toe_speed_m_s[i][uf]);
      }
      prev_ankle[i] = ankle;
      prev_toe[i] = toe;
      const bool before = f > 0 && detectors[i].contact();
      const bool now = detectors[i].Update(t.sole_height_m[i][uf] - params.ground_height_m, t.slide_m_s[i][uf]);
      t.contact[i][uf] = now ? 1 : 0;
      if (f > 0 && now != before) {
        // Date the change back to the start of the run that caused it.
        for (int b = std::max(1, f - detectors[i].last_run() + 1); b < f; ++b) t.contact[i][static_cast<size_t>(b)] = now ? 1 : 0;
      }
    }
  }
  return t;
}

// ---------------------------------------------------------------------------

TwoBoneIkResult SolveTwoBoneIk(const Eigen::Vector3d& hip, const Eigen::Vector3d& knee, const Eigen::Vector3d& ankle,
                               const Eigen::Matrix3d& hip_rotation, const Eigen::Matrix3d& knee_rotation,
                               const Eigen::Vector3d& target, const Eigen::Vector3d& bend_hint) {
  TwoBoneIkResult r{hip_rotation, knee_rotation, ankle, false};
  const Eigen::Vector3d thigh = knee - hip, shin = ankle - knee;
  const double l1 = thigh.norm(), l2 = shin.norm();
  if (!(l1 > 1e-12) || !(l2 > 1e-12)) {
    r.reached = (ankle - target).norm() <= 1e-9 * (1 + l1 + l2);
    return r;
  }
  const Eigen::Vector3d t1 = thigh / l1, s1 = shin / l2;
  Eigen::Vector3d to_target = target - hip;
  double d = to_target.norm();
  const double min_d = std::abs(l1 - l2), max_d = l1 + l2;
  const double tol = 1e-9 * max_d;
  r.reached = d <= max_d + tol && d >= min_d - tol;
  Eigen::Vector3d leg = ankle - hip;
  if (leg.norm() < 1e-9 * max_d) leg = thigh;
  const Eigen::Vector3d leg1 = leg.normalized();
  if (d < 1e-12 * max_d) to_target = leg1 * d;  // no direction: keep the leg's
  d = std::clamp(d, min_d, max_d);

  // Bending axis: the leg's own plane when clearly bent (forwards or to a
  // side), the plane of the leg and the hint (knee towards the toes) when
  // straight or bent backwards (its own plane's axis over ~105° from the
  // hint's; fully so beyond ~140°). Between the two the axis is blended,
  // never switched: a switch moved the knee 15-20 cm in one frame (5 m/s)
  // when a source leg with its knee turned out crossed the threshold. The
  // blend once spanned 75-105°: a wide stance bends the knee sideways (the
  // knee inside the slanted hip-ankle line, ~90° from the toes), and the
  // source's small swivels there swung the knee 4 cm in a frame.
  const Eigen::Vector3d hint = bend_hint - leg1 * bend_hint.dot(leg1);
  Eigen::Vector3d hint_axis = hint.cross(leg1);
  const double hint_norm = hint_axis.norm();
  const Eigen::Vector3d bent = t1.cross(s1);
  const double sin_bend = bent.norm();
  constexpr double kStraightLow = 0.026, kStraightHigh = 0.078;  // sin 1.5°, sin 4.5°
  Eigen::Vector3d axis;
  if (hint_norm >= 1e-9) {
    hint_axis /= hint_norm;
    double own = 0;
    if (sin_bend > 1e-12) {
      const Eigen::Vector3d own_axis = bent / sin_bend;
      own = SmoothStep((sin_bend - kStraightLow) / (kStraightHigh - kStraightLow)) *
            SmoothStep((own_axis.dot(hint_axis) + 0.75) / 0.5);
      axis = own * own_axis + (1 - own) * hint_axis;  // |axis|^2 >= 0.25 where own > 0
    } else {
      axis = hint_axis;
    }
    axis.normalize();
  } else if (sin_bend > 1e-12) {
    axis = bent / sin_bend;
  } else {
    axis = t1.unitOrthogonal();
  }
  // Turn the shin about the axis (through the knee) until the ankle is d
  // from the hip: with the shin split along the axis (s_par) and across it
  // (s_perp, and s_side a quarter turn further), thigh · shin(φ) = a0 +
  // a cos φ + b sin φ must equal (d² − l1² − l2²) / 2. φ0 = atan2(b, a) is
  // the straightest turn; the knee bends on from there in the axis' sense.
  // For the leg's own plane this is the textbook "wanted minus current bend";
  // for a blended plane it still lands the ankle at the distance.
  const Eigen::Vector3d s_par = axis * axis.dot(shin), s_perp = shin - s_par, s_side = axis.cross(s_perp);
  const double a0 = thigh.dot(s_par), a = thigh.dot(s_perp), b = thigh.dot(s_side);
  const double swing = std::hypot(a, b);
  const double want = 0.5 * (d * d - l1 * l1 - l2 * l2) - a0;
  double phi = 0;
  if (swing > 1e-12 * l1 * l2) {
    const double c = want / swing;
    if (c > 1 + 1e-9 || c < -1 - 1e-9) r.reached = false;  // the plane cannot reach d
    phi = std::atan2(b, a) + std::acos(std::clamp(c, -1.0, 1.0));
  }
  const Eigen::Matrix3d knee_turn = Eigen::AngleAxisd(phi, axis).toRotationMatrix();
  const Eigen::Vector3d ankle1 = knee + knee_turn * shin;
  const Eigen::Matrix3d hip_turn =
      Eigen::Quaterniond::FromTwoVectors(ankle1 - hip, to_target).toRotationMatrix();
  r.hip_rotation = hip_turn * hip_rotation;
  r.knee_rotation = hip_turn * knee_turn * knee_rotation;
  r.ankle = hip + hip_turn * (ankle1 - hip);
  return r;
}

// ---------------------------------------------------------------------------

Status ValidateFootPlantParams(const FootPlantParams& p) {
  KINEMO_RETURN_IF_ERROR(ValidateFootContactParams(p.contact, "feet.contact"));
  if (!std::isfinite(p.floor_height_m)) return InvalidField("feet.floor_height_m", "must be finite");
  if (!std::isfinite(p.blend_s) || p.blend_s < 0 || p.blend_s > 10) {
    return InvalidField("feet.blend_s", p.blend_s, " must be in [0, 10]");
  }
  if (!std::isfinite(p.max_foot_twist_deg) || p.max_foot_twist_deg < 0 || p.max_foot_twist_deg > 180) {
    return InvalidField("feet.max_foot_twist_deg", p.max_foot_twist_deg, " must be in [0, 180]");
  }
  if (!std::isfinite(p.held_foot_twist_deg) || p.held_foot_twist_deg < 0 || p.held_foot_twist_deg > 180) {
    return InvalidField("feet.held_foot_twist_deg", p.held_foot_twist_deg, " must be in [0, 180]");
  }
  if (!std::isfinite(p.twist_rate_deg_s) || p.twist_rate_deg_s < 0 || p.twist_rate_deg_s > 36000) {
    return InvalidField("feet.twist_rate_deg_s", p.twist_rate_deg_s, " must be in [0, 36000]");
  }
  if (!std::isfinite(p.max_foot_pivot_deg_s) || p.max_foot_pivot_deg_s < 0 || p.max_foot_pivot_deg_s > 36000) {
    return InvalidField("feet.max_foot_pivot_deg_s", p.max_foot_pivot_deg_s, " must be in [0, 36000]");
  }
  if (!std::isfinite(p.max_lock_distance_m) || p.max_lock_distance_m < 0 || p.max_lock_distance_m > 100) {
    return InvalidField("feet.max_lock_distance_m", p.max_lock_distance_m, " must be in [0, 100]");
  }
  if (!std::isfinite(p.max_lock_dwell_s) || p.max_lock_dwell_s < 0 || p.max_lock_dwell_s > 60) {
    return InvalidField("feet.max_lock_dwell_s", p.max_lock_dwell_s, " must be in [0, 60]");
  }
  if (!std::isfinite(p.step_s) || p.step_s < 0 || p.step_s > 10) {
    return InvalidField("feet.step_s", p.step_s, " must be in [0, 10]");
  }
  if (!std::isfinite(p.step_height_m) || p.step_height_m < 0 || p.step_height_m > 1) {
    return InvalidField("feet.step_height_m", p.step_height_m, " must be in [0, 1]");
  }
  if (!std::isfinite(p.release_distance_m) || p.release_distance_m < 0 || p.release_distance_m > 100) {
    return InvalidField("feet.release_distance_m", p.release_distance_m, " must be in [0, 100]");
  }
  if (!std::isfinite(p.step_height_per_m) || p.step_height_per_m < 0 || p.step_height_per_m > 10) {
    return InvalidField("feet.step_height_per_m", p.step_height_per_m, " must be in [0, 10]");
  }
  if (!std::isfinite(p.max_crouch_m) || p.max_crouch_m < 0 || p.max_crouch_m > 1) {
    return InvalidField("feet.max_crouch_m", p.max_crouch_m, " must be in [0, 1]");
  }
  if (!std::isfinite(p.max_crouch_s) || p.max_crouch_s < 0 || p.max_crouch_s > 60) {
    return InvalidField("feet.max_crouch_s", p.max_crouch_s, " must be in [0, 60]");
  }
  if (!std::isfinite(p.release_speed_m_s) || p.release_speed_m_s < 0 || p.release_speed_m_s > 100) {
    return InvalidField("feet.release_speed_m_s", p.release_speed_m_s, " must be in [0, 100]");
  }
  if (!std::isfinite(p.soft_reach_m) || p.soft_reach_m < 0 || p.soft_reach_m > 0.5) {
    return InvalidField("feet.soft_reach_m", p.soft_reach_m, " must be in [0, 0.5]");
  }
  if (!std::isfinite(p.max_knee_swivel_m_s) || p.max_knee_swivel_m_s < 0 || p.max_knee_swivel_m_s > 100) {
    return InvalidField("feet.max_knee_swivel_m_s", p.max_knee_swivel_m_s, " must be in [0, 100]");
  }
  if (!std::isfinite(p.knee_margin_m) || p.knee_margin_m < 0 || p.knee_margin_m > 0.5) {
    return InvalidField("feet.knee_margin_m", p.knee_margin_m, " must be in [0, 0.5]");
  }
  if (!std::isfinite(p.pointed_foot_m) || p.pointed_foot_m < 0 || p.pointed_foot_m > 0.1) {
    return InvalidField("feet.pointed_foot_m", p.pointed_foot_m, " must be in [0, 0.1]");
  }
  if (!std::isfinite(p.pointed_foot_speed_m_s) || p.pointed_foot_speed_m_s < 0 || p.pointed_foot_speed_m_s > 100) {
    return InvalidField("feet.pointed_foot_speed_m_s", p.pointed_foot_speed_m_s, " must be in [0, 100]");
  }
  if (!std::isfinite(p.reach_raise_m) || p.reach_raise_m < 0 || p.reach_raise_m > 0.5) {
    return InvalidField("feet.reach_raise_m", p.reach_raise_m, " must be in [0, 0.5]");
  }
  for (const auto& [name, v] : {std::pair<const char*, double>{"feet.lift_omega", p.lift_omega},
                                std::pair<const char*, double>{"feet.anchor_omega", p.anchor_omega}}) {
    if (!std::isfinite(v) || v < 0 || v > 1000) return InvalidField(name, v, " must be in [0, 1000] rad/s");
  }
  return absl::OkStatus();
}

FootPlantParams StandingFootPlantParams() {
  FootPlantParams p;
  // A lock that stays 35 cm from the animated foot for 0.3 s steps there:
  // with locks that held wherever the animation went, GC's output on held-out
  // BEAT2 speech stood 12.5 cm behind its feet on average for 40 s after one
  // blend had spread them to 40 cm (the real takes: 0.0 cm, the unplanted
  // output 3 cm).
  p.max_lock_distance_m = 0.35;
  p.max_lock_dwell_s = 0.3;
  p.release_distance_m = 0.15;
  // A stance the body must squat 8 cm to hold (the legs short of reach) for
  // 0.5 s steps, and a step's arc rises 0.2 m per metre it travels (up to
  // step_height_m): GMG on held-out BEAT2 speech stood 14 cm low for 3.5 s
  // over feet a blend had spread to 56 cm, each lock under 35 cm from its
  // animated foot; the speaker's own steps rise 4-8 cm for 15-30 cm of
  // travel and 7-11 cm for 30-60 cm (ankle above its standing height, both
  // takes). After 0.3 s, take 1 as it is stepped where the speaker was
  // about to step himself, and its ankles were lifted twice as often.
  p.max_crouch_m = 0.08;
  p.max_crouch_s = 0.5;
  p.step_height_per_m = 0.2;
  // A released foot goes back to the animated one no faster than the
  // speaker's steps (their peak horizontal ankle speed: 0.9-1.2 m/s median,
  // 1.76 at most, both takes). At 2 m/s the catch-ups peaked at 2.26 m/s
  // (median, held-out speech); at 1.2 m/s at 1.35, with ankle lift, slide
  // and the wrists unchanged.
  p.release_speed_m_s = 1.2;
  // Legs that ease into straightness (soft_reach_m) and knees that swivel
  // no faster than the speaker's: the knees' jerk on held-out BEAT2 speech
  // 109 -> 67 m/s³ (motion compare's knee_jerk_mean_m_s3, mean over GC, GC
  // online, GMG, BodySpeech, both folds; the speaker's 20-31). The speaker's own legs
  // stay 1.1 / 1.5 / 2.2 cm short of straight (hip-ankle distance under the
  // leg's length, 10th / 50th / 90th percentile, both takes).
  p.soft_reach_m = 0.015;
  p.max_knee_swivel_m_s = 0.8;
  p.anchor_omega = 12;
  p.reach_raise_m = 0.04;
  // 0.3 cm under the straight leg (the BEAT2 speaker's hips are 0.4-1.3 cm
  // under it): with 1 cm the leg he stands on bent 19 degrees in every
  // method's output against his 15, with 0.5 cm 15-16 (before the soft
  // reach, which bends it a little more: 0.3 cm with it keeps replanted
  // take 2's at 16.8, the source's 14.9).
  p.knee_margin_m = 0.003;
  // The pointed foot (see pointed_foot_m) keeps the leg stood on at its
  // reach more often; its heel comes up to 6 cm before the body drops for a
  // frame (pelvis vertical jerk of replanted take 1: 10.4 m/s³ with 4 cm,
  // 8.9 with 6 cm; the source's 6.5).
  p.pointed_foot_m = 0.02;
  // Its allowance changes at up to 0.1 m/s: following a sole the animation
  // lifts (0.4-0.6 m/s) the standing foot sank 1.3 cm in a frame, its knee
  // at 0.9 m/s for that frame (BEAT2 take 1 replanted); the knees' mean
  // jerk over the eight held-out outputs of gesture_loto 58.6 -> 52.3 m/s3
  // (0.05 m/s: 48.7, but GC's fold-2 Hellinger speed 0.200 -> 0.203).
  p.pointed_foot_speed_m_s = 0.1;
  p.reach_raise_m = 0.06;
  // A foot held where it stands while the animation lifts it (a weight
  // shift: release_distance_m) keeps within 30 degrees of its locked
  // orientation instead of 20, the limit changing at 50 deg/s. Pivoting
  // along with a lifted foot that points and flexes, the held foot rocked
  // onto its toes or its heel: replanted BEAT2 take 1's left ankle went
  // down to 2.0 cm over the floor (the speaker's own: 3.7 cm at the
  // lowest), GC's on held-out speech to 3.1 cm with the body 4.3 cm low
  // (its ankle-lift share, measured from that lowest height, 1.1 %).
  // And a locked foot pivots no faster than 180 deg/s: following an
  // animated toe-off at 300 deg/s the held foot's toes slipped 2.5 cm down
  // in a frame and its knee jumped 6.6 cm (2.0 m/s; GC online on held-out
  // speech, where the library's fastest knee moves at 1.0). docs/feet.md.
  p.held_foot_twist_deg = 30;
  p.twist_rate_deg_s = 50;
  p.max_foot_pivot_deg_s = 180;
  return p;
}

StatusOr<std::unique_ptr<FootPlanter>> FootPlanter::Create(const Skeleton& skeleton, const BodyRegionMap& regions,
                                                           double frame_time_s, const FootPlantParams& params) {
  KINEMO_RETURN_IF_ERROR(ValidateFootPlantParams(params));
  if (!std::isfinite(frame_time_s) || frame_time_s <= 0) {
    return InvalidField("frame_time_s", frame_time_s, " must be positive");
  }
  KINEMO_ASSIGN_OR_RETURN(FeetRig rig, FeetRig::Find(skeleton, regions));
  const Joint& root = skeleton.joint(rig.root);
  if (root.position_column[0] < 0 || root.position_column[1] < 0 || root.position_column[2] < 0) {
    return absl::FailedPreconditionError(
        kinemo::StrCat("skeleton: root joint '", root.name, "' has no X, Y and Z position channels"));
  }
  for (const LegJoints& leg : rig.legs) {
    for (int j : {leg.hip, leg.knee, leg.ankle}) {
      if (!skeleton.joint(j).has_euler_rotation()) {
        return absl::FailedPreconditionError(kinemo::StrCat(
            "skeleton: leg joint '", skeleton.joint(j).name, "' has no three-axis Euler rotation channels"));
      }
    }
  }
  return std::unique_ptr<FootPlanter>(new FootPlanter(skeleton, std::move(rig), frame_time_s, params));
}

FootPlanter::FootPlanter(const Skeleton& skeleton, FeetRig rig, double frame_time_s, const FootPlantParams& p)
    : skeleton_(skeleton), rig_(std::move(rig)), p_(p), dt_(frame_time_s) {
  units_per_m_ = 1.0 / p_.contact.meters_per_unit;
  blend_step_ = p_.blend_s > 0 ? std::min(1.0, dt_ / p_.blend_s) : 1.0;
  max_twist_rad_ = p_.max_foot_twist_deg * std::numbers::pi / 180;
  held_twist_rad_ = p_.held_foot_twist_deg * std::numbers::pi / 180;
  twist_rate_rad_s_ = p_.twist_rate_deg_s * std::numbers::pi / 180;
  pivot_rad_s_ = p_.max_foot_pivot_deg_s * std::numbers::pi / 180;
  max_lock_units_ = p_.max_lock_distance_m * units_per_m_;
  release_units_ = p_.release_distance_m * units_per_m_;
  knee_margin_units_ = p_.knee_margin_m * units_per_m_;
  soft_units_ = p_.soft_reach_m * units_per_m_;
  swivel_units_ = p_.max_knee_swivel_m_s * units_per_m_;
  pointed_units_ = p_.pointed_foot_m * units_per_m_;
  pointed_speed_units_ = p_.pointed_foot_speed_m_s * units_per_m_;
  reach_raise_units_ = p_.reach_raise_m * units_per_m_;
  // A planted foot leaves its contact only by lifting: one the animation
  // slides along the floor (a blend between clips that stand differently
  // moves each foot up to ~10 cm at 0.6-0.75 m/s) stays locked, and follows
  // only beyond max_lock_distance_m.
  FootContactParams contact = p_.contact;
  contact.exit_speed_m_s = std::numeric_limits<double>::infinity();
  for (Foot& f : feet_) f.detector = FootContactDetector(contact, dt_);
  pos_.resize(static_cast<size_t>(skeleton_.num_joints()));
  rot_.resize(pos_.size());
  // Planting reads only the legs (hip, knee, ankle, toe, sole points, the
  // hip's parent) and the root: the forward kinematics of each frame poses
  // those chains, not the arms and fingers.
  std::vector<int> rig_joints = {rig_.root, rig_.pelvis};
  for (const LegJoints& leg : rig_.legs) {
    for (int j : {leg.hip, leg.knee, leg.ankle, leg.toe}) rig_joints.push_back(j);
    for (const SolePoint& sp : leg.sole) rig_joints.push_back(sp.joint);
  }
  leg_chain_ = JointsWithAncestors(skeleton_, rig_joints);
  prev_out_.resize(static_cast<size_t>(skeleton_.num_channels()));
}

namespace {

// One step of a critically damped spring (x, v) toward `goal` at angular
// frequency omega over dt (exact for a constant goal); omega 0 = at once.
void FollowSpring(double goal, double omega, double dt, double* x, double* v) {
  if (!(omega > 0)) {
    *x = goal;
    *v = 0;
    return;
  }
  const double j0 = *x - goal, j1 = *v + j0 * omega, e = std::exp(-omega * dt);
  *x = e * (j0 + j1 * dt) + goal;
  *v = e * (*v - j1 * omega * dt);
}

}  // namespace

void FootPlanter::Apply(std::span<double> frame) {
  if (!p_.enabled) return;
  if (!ComputeWorldPoseOf(skeleton_, frame, leg_chain_, pos_, rot_).ok()) return;  // wrong frame size: left as is
  const bool first = frames_ == 0;
  const double mpu = p_.contact.meters_per_unit;
  const double floor_units = p_.floor_height_m * units_per_m_;
  const std::array<double, 2> sole = SoleHeights(rig_, pos_, rot_);
  std::array<double, 2> old_lock{};
  std::array<bool, 2> engaged{};
  std::array<double, 2> animated_slide{};
  for (size_t i = 0; i < 2; ++i) {
    Foot& foot = feet_[i];
    const LegJoints& leg = rig_.legs[i];
    const Eigen::Vector3d& ankle = pos_[static_cast<size_t>(leg.ankle)];
    const Eigen::Vector3d& toe = leg.toe >= 0 ? pos_[static_cast<size_t>(leg.toe)] : ankle;
    const double slide =
        first ? 0.0
              : std::min(HorizontalDistance(ankle, foot.prev_ankle), HorizontalDistance(toe, foot.prev_toe)) * mpu / dt_;
    animated_slide[i] = slide;
    const bool was = !first && foot.planted;
    bool now = foot.detector.Update(sole[i] * mpu - p_.contact.ground_height_m, slide);
    foot.held = false;
    // The animation lifts a planted foot: it steps only when its lock is
    // further than release_distance_m from where the animation has it (a
    // weight shift or a step in place keeps the foot where it stands).
    if (!now && was && release_units_ > 0 &&
        HorizontalDistance(foot.lock, ankle + Eigen::Vector3d(offset_.x(), 0, offset_.y())) < release_units_) {
      now = true;
      foot.held = true;
    }
    foot.planted = now;
    engaged[i] = now && !was;
    old_lock[i] = foot.lock_weight;
    if (now) {
      foot.lock_weight = 1;
      foot.floor_weight = first ? 1.0 : std::min(1.0, foot.floor_weight + blend_step_);
    } else {
      foot.lock_weight = std::max(0.0, foot.lock_weight - blend_step_);
      foot.floor_weight = std::max(0.0, foot.floor_weight - blend_step_);
    }
  }
  // The foot's orientation (locked, or returning to the animated one) and its
  // sole under that orientation.
  std::array<Eigen::Matrix3d, 2> foot_rotation;
  std::array<double, 2> foot_sole;
  for (size_t i = 0; i < 2; ++i) {
    Foot& foot = feet_[i];
    const LegJoints& leg = rig_.legs[i];
    const size_t a = static_cast<size_t>(leg.ankle);
    const Eigen::Quaterniond animated(rot_[a]);
    if (engaged[i]) foot.lock_rotation = animated.slerp(SmoothStep(old_lock[i]), foot.lock_rotation);
    // A foot turned further than its allowance from the animation pivots
    // along, no faster than max_foot_pivot_deg_s. The allowance is
    // max_twist, or held_twist for a foot held only because its lift is not
    // a step (it stays flatter), moving between them at twist_rate.
    const double goal = foot.held ? std::max(max_twist_rad_, held_twist_rad_) : max_twist_rad_;
    if (foot.twist_allow < 0 || twist_rate_rad_s_ <= 0) {
      foot.twist_allow = goal;
    } else {
      foot.twist_allow += std::clamp(goal - foot.twist_allow, -twist_rate_rad_s_ * dt_, twist_rate_rad_s_ * dt_);
    }
    const double twist = animated.angularDistance(foot.lock_rotation);
    if (twist > foot.twist_allow) {
      const Eigen::Quaterniond edge = animated.slerp(foot.twist_allow / twist, foot.lock_rotation);
      const double turn = foot.lock_rotation.angularDistance(edge), most = pivot_rad_s_ * dt_;
      foot.lock_rotation = most > 0 && turn > most ? foot.lock_rotation.slerp(most / turn, edge) : edge;
    }
    const double wl = SmoothStep(foot.lock_weight);
    foot_rotation[i] = wl > 0 ? animated.slerp(wl, foot.lock_rotation).toRotationMatrix() : rot_[a];
    if (wl > 0) {
      const Eigen::Matrix3d turn = foot_rotation[i] * rot_[a].transpose();
      double lowest = INFINITY;
      for (const SolePoint& sp : leg.sole) {
        const size_t j = static_cast<size_t>(sp.joint);
        lowest = std::min(lowest, (turn * (pos_[j] + rot_[j] * sp.local - pos_[a])).y());
      }
      foot_sole[i] = pos_[a].y() + lowest;
    } else {
      foot_sole[i] = sole[i];
    }
  }
  // Of two feet in contact, the lower one (its toes pointed down: a relaxed
  // leg's foot) counts as standing where the other stands, up to
  // pointed_foot_m (its toes are turned up to the floor below, step 5), so
  // the floor lift and that leg keep the animation's heights.
  std::array<double, 2> sink{};
  if (pointed_units_ > 0 && feet_[0].floor_weight > 0 && feet_[1].floor_weight > 0) {
    const size_t low = foot_sole[0] < foot_sole[1] ? 0 : 1;
    sink[low] = std::min(pointed_units_, foot_sole[1 - low] - foot_sole[low]) * SmoothStep(feet_[1 - low].floor_weight);
  }
  // ... changing no faster than pointed_foot_speed_m_s.
  for (size_t i = 0; i < 2; ++i) {
    if (pointed_speed_units_ > 0 && !first) {
      const double most = pointed_speed_units_ * dt_;
      sink[i] = sink_[i] + std::clamp(sink[i] - sink_[i], -most, most);
    }
    sink_[i] = sink[i];
  }
  // 1. Root anchoring: cancel the mean glide of the locked ankles. The body
  // follows the correction through a spring (the locked legs absorb the lag),
  // so the ankles' own jerk does not reach the whole body.
  if (p_.anchor_root && !first) {
    double weight = 0;
    Eigen::Vector2d glide = Eigen::Vector2d::Zero();
    for (size_t i = 0; i < 2; ++i) {
      const double w = SmoothStep(feet_[i].lock_weight);
      const Eigen::Vector3d d = pos_[static_cast<size_t>(rig_.legs[i].ankle)] - feet_[i].prev_ankle;
      glide += w * Eigen::Vector2d(d.x(), d.z());
      weight += w;
    }
    anchor_ -= glide / std::max(1.0, weight);
    for (int k = 0; k < 2; ++k) FollowSpring(anchor_(k), p_.anchor_omega, dt_, &offset_(k), &offset_v_(k));
  }
  // 2. Floor: the lift that puts the lowest sole among the contacts (a
  // weighted minimum, continuous in the weights) on the floor; held without
  // contacts.
  if (p_.floor) {
    double sum_w = 0, mean = 0, top = 0;
    for (size_t i = 0; i < 2; ++i) {
      const double w = SmoothStep(feet_[i].floor_weight);
      sum_w += w;
      mean += w * (foot_sole[i] + sink[i]);
      top = std::max(top, w);
    }
    if (sum_w > 0) {
      mean /= sum_w;
      double lowest = INFINITY;
      for (size_t i = 0; i < 2; ++i) {
        const double w = SmoothStep(feet_[i].floor_weight);
        if (w > 0) lowest = std::min(lowest, mean + w * (foot_sole[i] + sink[i] - mean));
      }
      floor_lift_ += top * ((floor_units - lowest) - floor_lift_);
    }
  }
  const Eigen::Vector3d across_shift(offset_.x(), 0, offset_.y());
  // 3. Locks: each foot's target, horizontally (vertically below).
  std::array<Eigen::Vector3d, 2> target;
  std::array<double, 2> step_lift{};
  std::array<bool, 2> solve{};
  // Squatting to hold a stance (max_crouch_m): the lock further from its
  // animated foot steps.
  int crouch_step = -1;
  if (p_.max_crouch_m > 0 && crouch_s_ >= p_.max_crouch_s) {
    double far_of[2];
    for (size_t i = 0; i < 2; ++i) {
      const Eigen::Vector3d shown = pos_[static_cast<size_t>(rig_.legs[i].ankle)] + across_shift;
      far_of[i] = std::hypot(feet_[i].lock.x() - shown.x(), feet_[i].lock.z() - shown.z());
    }
    const int i = far_of[1] > far_of[0] ? 1 : 0;
    if (far_of[i] > release_units_) crouch_step = i;
  }
  for (size_t i = 0; i < 2; ++i) {
    Foot& foot = feet_[i];
    const LegJoints& leg = rig_.legs[i];
    const size_t a = static_cast<size_t>(leg.ankle);
    const Eigen::Vector3d shown = pos_[a] + across_shift;
    if (engaged[i]) {
      // Lock where the foot is drawn now (still fading from an older lock?).
      foot.lock = shown + SmoothStep(old_lock[i]) * (foot.lock - shown);
      if (foot.drawn_limited) {  // still on its way: lock where it is drawn
        foot.lock.x() = foot.drawn.x();
        foot.lock.z() = foot.drawn.y();
      }
    }
    // A lock further than max_lock_distance from the animated ankle steps
    // there, one foot at a time: while the other foot steps, this one holds
    // its lock and steps after. Dragging it instead slid BEAT2 take 1 on
    // the Quaternius man at 0.031 m/s p95 (0.4-0.5 m/s while dragged).
    // max_lock_distance_m 0: locks hold wherever the animation goes.
    const Eigen::Vector2d apart(foot.lock.x() - shown.x(), foot.lock.z() - shown.z());
    const double far = apart.norm();
    // Step only while the other foot stands (never both in the air).
    const bool other_stands = feet_[1 - i].step < 0 && feet_[1 - i].lock_weight >= 1;
    // A lock that stays far for max_lock_dwell_s: a blend that passes by
    // does not make the foot step.
    const bool too_far = max_lock_units_ > 0 && far > max_lock_units_ && foot.lock_weight >= 1;
    foot.far_s = too_far ? foot.far_s + dt_ : 0;
    const bool squats = crouch_step == static_cast<int>(i) && foot.lock_weight >= 1;
    if ((squats || (too_far && foot.far_s >= p_.max_lock_dwell_s)) && foot.step < 0 && p_.step_s > 0 &&
        other_stands) {
      if (squats) crouch_s_ = 0;
      foot.step = 0;
      foot.step_from = foot.lock;
      // The travel (the middle 75 % of the step, a smoothstep: its peak
      // speed 1.5x the mean) no faster than a released foot goes: a 35-45 cm
      // step over 0.3 s moved the foot at 2.3-2.9 m/s, where the speaker's
      // own feet peak at 1.76 (GMG on held-out BEAT2 speech: an ankle at
      // 2.5 m/s, the fastest joint of the output).
      foot.step_len_s = p_.step_s;
      foot.step_height = p_.step_height_m * units_per_m_;
      if (p_.step_height_per_m > 0) foot.step_height = std::min(foot.step_height, p_.step_height_per_m * far);
      if (p_.release_speed_m_s > 0)
        foot.step_len_s = std::max(p_.step_s, 1.5 * (far / units_per_m_) / (0.75 * p_.release_speed_m_s));
    }
    if (foot.step >= 0) {
      foot.step = std::min(1.0, foot.step + dt_ / foot.step_len_s);
      // Lift first (the first 15 % of the step), then travel; land at 1.
      const double travel = SmoothStep(std::clamp((foot.step - 0.15) / 0.75, 0.0, 1.0));
      foot.lock.x() = foot.step_from.x() + travel * (shown.x() - foot.step_from.x());
      foot.lock.z() = foot.step_from.z() + travel * (shown.z() - foot.step_from.z());
      step_lift[i] = foot.step_height * std::sin(std::numbers::pi * foot.step);
      if (foot.step >= 1) foot.step = -1;  // landed: locked here
    } else if (max_lock_units_ > 0 && far > max_lock_units_ && feet_[1 - i].step < 0) {
      foot.lock.x() = shown.x() + apart.x() * (max_lock_units_ / far);
      foot.lock.z() = shown.z() + apart.y() * (max_lock_units_ / far);
    }
    target[i] = shown;
    // Leaving a contact the foot rises first, then travels: a released lock
    // holds horizontally for the first 40 % of its fade.
    const double wl = SmoothStep(std::min(1.0, foot.lock_weight / 0.6));
    target[i].x() += wl * (foot.lock.x() - shown.x());
    target[i].z() += wl * (foot.lock.z() - shown.z());
    // Out of its lock the foot goes where that puts it no faster than
    // release_speed_m_s (a lock 0.33 m from the animated foot was caught up
    // in 0.13 s: ankles at 4-5 m/s on BEAT2 speech).
    const Eigen::Vector2d wanted(target[i].x(), target[i].z());
    if (p_.release_speed_m_s > 0 && !first && wl < 1) {
      Eigen::Vector2d to = wanted - foot.drawn;
      // A free foot the animation holds still (under 5 cm/s) just above the
      // contact height, that the lowered body puts on the floor (its sole
      // within 1 cm of it), stays where it is drawn, up to release_distance_m
      // (at least 15 cm) from where the body takes it: following the body it
      // glided along the floor (GMG on held-out BEAT2 speech: 19 cm at up
      // to 0.6 m/s while the other foot stood; docs/feet.md).
      const bool floored = wl == 0 && foot_sole[i] + lift_ <= floor_units + kFlooredHeightM * units_per_m_ &&
                           animated_slide[i] < kFlooredStillMPerS &&
                           to.norm() < std::max(release_units_, 0.15 * units_per_m_);
      if (floored) to.setZero();
      const double most = p_.release_speed_m_s * units_per_m_ * dt_, dist = to.norm();
      foot.drawn += dist > most ? to * (most / dist) : to;
      // Held back (by the speed limit or the floor): a contact starting now
      // locks where the foot is drawn, not where the animation has it.
      foot.drawn_limited = dist > most || floored;
      target[i].x() = foot.drawn.x();
      target[i].z() = foot.drawn.y();
    } else {
      foot.drawn = wanted;
      foot.drawn_limited = false;
    }
    foot.prev_ankle = pos_[a];
    foot.prev_toe = leg.toe >= 0 ? pos_[static_cast<size_t>(leg.toe)] : pos_[a];
    solve[i] = foot.lock_weight > 0 || (target[i] - shown).squaredNorm() > 1e-18 * (1 + shown.squaredNorm());
  }
  // Vertical target of a foot when the root is lifted by L: its sole on the
  // floor as far as its floor weight says, else where the lifted animation
  // has it; never under the floor.
  auto target_y = [&](size_t i, double L) {
    const double ankle_y = pos_[static_cast<size_t>(rig_.legs[i].ankle)].y();
    if (!p_.floor) return ankle_y + L + step_lift[i];
    const double fw = SmoothStep(feet_[i].floor_weight);
    const double on_floor = ankle_y + floor_units - foot_sole[i] - sink[i];
    return std::max(ankle_y + L + fw * (on_floor - ankle_y - L), on_floor) + step_lift[i];
  };
  // 4. Reach: the highest lift at which every target lies within kReach of
  // its leg's length (a target beyond reach horizontally does not count:
  // lowering cannot help).
  auto reach_limit = [&](double L) {
    double limit = INFINITY;
    for (size_t i = 0; i < 2; ++i) {
      if (!solve[i]) continue;
      const Eigen::Vector3d& hip = pos_[static_cast<size_t>(rig_.legs[i].hip)];
      const double reach = kReach * LegLength(i);
      const double across = HorizontalDistance(hip + across_shift, target[i]);
      if (across >= reach) continue;
      // hip.y + L' − target_y(L') ≤ room, target_y piecewise affine in L'.
      const double room = std::sqrt(reach * reach - across * across);
      const double gap = hip.y() + L - target_y(i, L);
      const double slope = 1 - (target_y(i, L + 1) - target_y(i, L));
      if (gap > room) {
        limit = std::min(limit, slope > 1e-9 ? L - (gap - room) / slope : L);
      } else if (slope > 1e-9) {
        limit = std::min(limit, L + (room - gap) / slope);
      }
    }
    return limit;
  };
  // The root's lift: the floor's, kept knee_margin_m under the reach limit,
  // followed through a spring (the animation's own vertical motion stays as
  // it is; contacts coming and going move the body smoothly); what is still
  // beyond reach is taken off this frame only.
  {
    const double goal = std::min(floor_lift_, reach_limit(lift_) - knee_margin_units_);
    if (first) {
      lift_ = std::isfinite(goal) ? goal : floor_lift_;
      lift_v_ = 0;
    } else if (std::isfinite(goal)) {
      FollowSpring(goal, p_.lift_omega, dt_, &lift_, &lift_v_);
    }
    crouch_s_ = p_.max_crouch_m > 0 && floor_lift_ - lift_ > p_.max_crouch_m * units_per_m_ ? crouch_s_ + dt_ : 0;
  }
  // What is still beyond reach: the feet short of it rise (the heel comes up,
  // up to reach_raise_m), the body drops (this frame only) by the rest.
  const double short_of_reach = std::max(0.0, lift_ - reach_limit(lift_));
  const double raise = std::min(short_of_reach, reach_raise_units_);
  const double drop = short_of_reach - raise;
  const Eigen::Vector3d shift(offset_.x(), lift_ - drop, offset_.y());
  const Joint& root = skeleton_.joint(rig_.root);
  frame[static_cast<size_t>(root.position_column[0])] += shift.x();
  frame[static_cast<size_t>(root.position_column[1])] += shift.y();
  frame[static_cast<size_t>(root.position_column[2])] += shift.z();
  for (size_t i = 0; i < 2; ++i) {
    target[i].y() = target_y(i, shift.y());
    if (raise > 0 && solve[i]) {
      const Eigen::Vector3d& hip = pos_[static_cast<size_t>(rig_.legs[i].hip)];
      const double reach = kReach * LegLength(i);
      const double across = HorizontalDistance(hip + across_shift, target[i]);
      if (across < reach) {
        const double lowest = hip.y() + shift.y() - std::sqrt(reach * reach - across * across);
        target[i].y() = std::max(target[i].y(), std::min(lowest, target[i].y() + raise));
      }
    }
  }
  // The pointed foot's toes turn up about its ankle until every sole point
  // is on or over the floor (by the largest angle one of them needs, at
  // most kMaxToesUpRad).
  for (size_t i = 0; i < 2; ++i) {
    if (sink[i] <= 0) continue;
    const LegJoints& leg = rig_.legs[i];
    const size_t a = static_cast<size_t>(leg.ankle);
    const Eigen::Matrix3d turn = foot_rotation[i] * rot_[a].transpose();
    double pitch = 0;
    Eigen::Vector3d axis = Eigen::Vector3d::Zero();
    for (const SolePoint& sp : leg.sole) {
      const size_t j = static_cast<size_t>(sp.joint);
      const Eigen::Vector3d r = turn * (pos_[j] + rot_[j] * sp.local - pos_[a]);
      const double under = floor_units - (target[i].y() + r.y());
      const double ahead = Eigen::Vector2d(r.x(), r.z()).norm();
      if (!(under > 0) || ahead < 1e-9) continue;
      const double need = std::asin(std::min(1.0, under / ahead));
      if (need > pitch) {
        pitch = need;
        axis = Eigen::Vector3d(r.x(), 0, r.z()).normalized().cross(Eigen::Vector3d::UnitY());
      }
    }
    if (pitch > 0) foot_rotation[i] = Eigen::AngleAxisd(std::min(pitch, kMaxToesUpRad), axis).toRotationMatrix() * foot_rotation[i];
  }
  // 5. Leg IK, on every leg: a free leg's target is its own ankle (or where
  // the floor pushes it up), so the solve changes only a knee bent away from
  // the toes (turned towards them,
  // continuously in the bend's direction). Solving only the planted legs let
  // an assembled knee bent backwards (blends of two segments' hips and knees;
  // the speaker's own knee is never 2 cm behind the hip-ankle line) show on a
  // free leg and flip forwards when it planted: 20 cm in one frame (6.6 m/s).
  for (size_t i = 0; i < 2; ++i) SolveLeg(static_cast<int>(i), target[i] - shift, foot_rotation[i], frame);
  std::copy(frame.begin(), frame.end(), prev_out_.begin());
  ++frames_;
}

// IK in the animated (unshifted) world: the shift is a translation, so the
// same rotations are right in the shifted one.
void FootPlanter::SolveLeg(int foot, const Eigen::Vector3d& target, const Eigen::Matrix3d& ankle_rotation,
                           std::span<double> frame) {
  const LegJoints& leg = rig_.legs[static_cast<size_t>(foot)];
  const size_t h = static_cast<size_t>(leg.hip), k = static_cast<size_t>(leg.knee), a = static_cast<size_t>(leg.ankle);
  const Eigen::Vector3d eased =
      EaseNearFullReach(pos_[h], target, LegLength(static_cast<size_t>(foot)), soft_units_);
  TwoBoneIkResult ik = SolveTwoBoneIk(pos_[h], pos_[k], pos_[a], rot_[h], rot_[k], eased,
                                      ToeDirection(skeleton_, leg, pos_, rot_));
  if (swivel_units_ > 0) LimitKneeSwivel(static_cast<size_t>(foot), &ik);
  const Eigen::Matrix3d& parent = rot_[static_cast<size_t>(skeleton_.joint(leg.hip).parent)];
  const std::array<std::pair<int, Eigen::Matrix3d>, 3> locals = {
      std::pair<int, Eigen::Matrix3d>{leg.hip, parent.transpose() * ik.hip_rotation},
      std::pair<int, Eigen::Matrix3d>{leg.knee, ik.hip_rotation.transpose() * ik.knee_rotation},
      std::pair<int, Eigen::Matrix3d>{leg.ankle, ik.knee_rotation.transpose() * ankle_rotation}};
  const std::span<const double> reference = frames_ > 0 ? std::span<const double>(prev_out_) : frame;
  for (const auto& [j, local] : locals) {
    const Joint& joint = skeleton_.joint(j);
    Eigen::Vector3d ref;
    for (size_t c = 0; c < 3; ++c) ref[static_cast<Eigen::Index>(c)] = reference[static_cast<size_t>(joint.rotation_column[c])];
    const Eigen::Vector3d angles = MatrixToEuler(local, joint.rotation_axis, ref);
    for (size_t c = 0; c < 3; ++c) frame[static_cast<size_t>(joint.rotation_column[c])] = angles[static_cast<Eigen::Index>(c)];
  }
}

double FootPlanter::LegLength(size_t foot) const {
  const LegJoints& leg = rig_.legs[foot];
  const Eigen::Vector3d& knee = pos_[static_cast<size_t>(leg.knee)];
  return (knee - pos_[static_cast<size_t>(leg.hip)]).norm() + (pos_[static_cast<size_t>(leg.ankle)] - knee).norm();
}

void FootPlanter::LimitKneeSwivel(size_t foot, TwoBoneIkResult* ik) {
  const LegJoints& leg = rig_.legs[foot];
  const size_t h = static_cast<size_t>(leg.hip), k = static_cast<size_t>(leg.knee);
  Foot& f = feet_[foot];
  const Eigen::Vector3d line = ik->ankle - pos_[h];
  if (line.norm() <= 1e-9) return;
  // The knee's offset from the hip-ankle line, now and (projected) last frame.
  const Eigen::Vector3d u = line.normalized();
  const Eigen::Vector3d thigh = ik->hip_rotation * (rot_[h].transpose() * (pos_[k] - pos_[h]));
  Eigen::Vector3d side = thigh - u * u.dot(thigh);
  const Eigen::Vector3d before = f.knee_side - u * u.dot(f.knee_side);
  const double r = side.norm();
  if (frames_ > 0 && r > 1e-9 && before.norm() > 1e-9) {
    const double turn = std::atan2(u.dot(before.cross(side)), before.dot(side));
    const double most = swivel_units_ * dt_ / r;
    if (std::abs(turn) > most) {
      // The whole leg turns back about the line: the ankle stays.
      const Eigen::Matrix3d back = Eigen::AngleAxisd(std::copysign(most, turn) - turn, u).toRotationMatrix();
      ik->hip_rotation = back * ik->hip_rotation;
      ik->knee_rotation = back * ik->knee_rotation;
      side = back * side;
    }
  }
  f.knee_side = side;
}

Status PlantFeet(Clip* clip, const BodyRegionMap& regions, const FootPlantParams& params) {
  if (!params.enabled) return absl::OkStatus();
  KINEMO_RETURN_IF_ERROR(clip->Validate());
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<FootPlanter> planter,
                          FootPlanter::Create(clip->skeleton, regions, clip->frame_time_s, params));
  for (int f = 0; f < clip->num_frames(); ++f) {
    planter->Apply(std::span<double>(clip->frames.data() + static_cast<Eigen::Index>(f) * clip->frames.cols(),
                                     static_cast<size_t>(clip->frames.cols())));
  }
  return absl::OkStatus();
}

}  // namespace kinemo::motion
