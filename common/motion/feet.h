// Foot contacts and planted feet: detection of the frames in which a foot
// stands on the floor, and a lower-body fix that keeps standing feet still
// without touching the upper body. Plain C++ (Eigen); see docs/feet.md.
//
// Terms (y is up, the floor is the plane y = floor_height_m of the file):
//   sole      the lowest point of a foot: the minimum height over the foot
//             joint, every joint below it and their End Sites (the skeletons
//             have no heel or skin, so a flat foot's sole is its toe joint or
//             toe tip);
//   slide     a foot's horizontal speed, taken as the slower of its ankle and
//             its toe joint: a foot that pivots about its ankle or rolls onto
//             its toes is not sliding, one that translates moves both;
//   ground    the height the contact detector measures from: the floor, or
//             (EstimateGroundHeight) the level a clip's feet actually stand at,
//             since motion capture often floats a few centimetres.
//
// Contact detection (FootContactDetector) is causal, one foot per detector:
// a foot enters contact when its sole is within enter_height_m of the ground
// and it slides slower than enter_speed_m_s, and leaves when the sole rises
// above exit_height_m or it slides faster than exit_speed_m_s (hysteresis);
// either condition must hold for enter_debounce_s / exit_debounce_s before
// the state changes (minimum durations). The first frame of a stream enters
// contact on height alone. AnalyzeFeet runs it over a clip and, knowing the
// future, dates each change back to the first frame of its debounce run.
//
// Planting (FootPlanter), per frame, causal and allocation-free. Its
// detectors leave a contact only by height (exit_height_m), never by speed: a
// foot the animation slides along the floor stays locked (see 3). A foot the
// animation lifts leaves its lock only when the lock is further than
// release_distance_m from the animated foot (0 = always): for a person
// standing and talking (StandingFootPlantParams) a weight shift or a step in
// place keeps the foot where it stands.
//  1. Root anchoring. The root's horizontal position is corrected by minus the
//     weighted mean horizontal displacement of the ankles in contact (weight =
//     each foot's lock weight), so that a body whose feet glide together (a
//     blend between clips that stand at different places, a re-based root,
//     per-clip sway) stays over its feet, while a body that sways over still
//     feet is untouched. The correction is followed through a critically
//     damped spring (anchor_omega; 0 = at once): the locked legs absorb the
//     lag, and an ankle's own jerk does not move the whole body.
//  2. Floor. The lift that puts the lowest sole among the contacts on the
//     floor (a weighted minimum, continuous as contacts come and go; held
//     while no foot is in contact; of two contacts the lower counts as level
//     with the other up to pointed_foot_m, and before step 5 its toes turn
//     up about its ankle to the floor), capped knee_margin_m under the highest
//     lift at which every locked leg reaches its target (step 4), is followed
//     through a spring (lift_omega): the animation's own vertical motion
//     passes unchanged, the correction moves slowly.
//  3. Locks. When a foot enters contact its ankle's position and world
//     orientation are locked as they are shown (so engaging a lock never moves
//     the foot, and the toes stay where they stand too); when it leaves, the
//     foot rises and then returns to the animated one over blend_s
//     (horizontally it holds for the first 40 %; smoothstep, slerp).
//     Two bounds keep a long contact natural when the animation changes its
//     stance underneath (a blend into a clip that stands differently): a
//     locked foot turned more than max_foot_twist_deg from the animated one
//     pivots along (about the ankle, so the ankle stays; at most
//     max_foot_pivot_deg_s; a foot held through a lift that is not a step
//     only beyond held_foot_twist_deg), and a lock further
//     than max_lock_distance_m (0 = never) from the animated ankle makes the
//     foot step there (retargeting: motion capture of a person shifting their
//     weight lifts a foot 3-4 cm, under exit_height_m): over step_s the lock
//     travels to the animated ankle (after a short lift start) while the sole
//     rises step_height_m and comes down (a sine arc), then the foot is
//     locked where it landed. A foot steps only while the other stands
//     locked (a far lock holds while the other steps); it is dragged along
//     only while the other is off the floor or step_s is 0. Vertically the
//     target puts the foot's own sole (under the locked orientation) on the
//     floor, faded in over blend_s; no foot's sole goes under the floor.
//  4. Reach. A target beyond its leg's reach (the animation moves the hips
//     away from a locked foot faster than the lift follows) raises that foot
//     by up to reach_raise_m (the heel comes up); the rest lowers the root
//     for this frame only, just enough for every target to lie within 99.95%
//     of its leg's length.
//  5. Leg IK (SolveTwoBoneIk) on both legs (a free leg's target is its own
//     ankle: only a knee bent away from the toes changes; within
//     soft_reach_m of full extension the target first rises a little so the
//     leg eases into straightness): analytic hip–knee–ankle, the knee turning in
//     its bending plane (or, for a straight or over-straight leg, in the plane
//     of the leg and the toes, so it never bends backwards), the ankle given
//     the foot's world orientation of step 3 (the animated one outside
//     contacts); targets still unreachable are approached along the
//     hip → target line.
//  6. Output: the root's position channels and the Euler channels of the hip,
//     knee and ankle joints (MatrixToEuler with the previous output frame as
//     reference). No other channel changes, so every joint outside the legs
//     keeps its position relative to the root.
// PlantFeet runs the same planter over a whole clip: offline and online
// planting give identical frames.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::motion {

// A point of a foot: a joint, or its End Site (local offset in its frame).
struct SolePoint {
  int joint = -1;
  Eigen::Vector3d local = Eigen::Vector3d::Zero();
};

// One leg: hip (thigh root) → knee → ankle (the foot joint of
// FindKeyJoints), the toe below the ankle (-1 if none) and the sole points.
struct LegJoints {
  int hip = -1;
  int knee = -1;
  int ankle = -1;
  int toe = -1;
  std::vector<SolePoint> sole;
};

// The joints planting works on.
struct FeetRig {
  std::array<LegJoints, 2> legs;  // left, right
  int pelvis = -1;                // nearest common ancestor of the two hips
  int root = 0;                   // joint 0: its position channels move the body

  // Finds the legs from a region map (FindKeyJoints' feet). FAILED_PRECONDITION
  // when the skeleton has no feet, a foot has no knee and hip above it, or
  // the legs share no ancestor.
  static StatusOr<FeetRig> Find(const Skeleton& skeleton, const BodyRegionMap& regions);
};

struct FootContactParams {
  double meters_per_unit = 0.01;  // skeleton scale
  double ground_height_m = 0;     // heights are measured from here
  double enter_height_m = 0.05;   // sole above ground to enter contact, at most
  double exit_height_m = 0.08;    // sole above ground to leave contact, more than
  double enter_speed_m_s = 0.3;   // slide to enter contact, at most
  double exit_speed_m_s = 0.6;    // slide to leave contact, more than
  double enter_debounce_s = 0.05; // the entry condition holds this long (>= 1 frame)
  double exit_debounce_s = 0.1;   // the exit condition holds this long (>= 1 frame)
};
// INVALID_ARGUMENT naming the field (prefixed by `field`).
Status ValidateFootContactParams(const FootContactParams& p, std::string_view field = "contact");

// Causal contact state of one foot.
class FootContactDetector {
 public:
  FootContactDetector() = default;
  FootContactDetector(const FootContactParams& params, double frame_time_s);
  // Feeds one frame: sole height above the ground and slide (speed_m_s is
  // ignored on the first frame). Returns the contact state after it.
  bool Update(double sole_height_m, double speed_m_s);
  bool contact() const { return contact_; }
  // Frames the condition that changed the state last had held (1 = none).
  int last_run() const { return last_run_; }

 private:
  FootContactParams p_;
  int enter_frames_ = 1, exit_frames_ = 1;
  bool started_ = false, contact_ = false;
  int run_ = 0, last_run_ = 1;
};

// Per-frame measurements of both feet over a clip.
struct FeetTrack {
  int num_frames = 0;
  double frame_time_s = 0;
  // [foot][frame]; speeds are from frame f-1 to f (0 at f = 0), horizontal.
  std::array<std::vector<double>, 2> sole_height_m;  // above the floor (y = 0)
  std::array<std::vector<double>, 2> ankle_speed_m_s, toe_speed_m_s, slide_m_s;
  std::array<std::vector<uint8_t>, 2> contact;
  std::vector<Eigen::Vector2d> pelvis_xz_m;  // horizontal pelvis position per frame
  double ground_height_m = 0;                // the ground contacts were measured from
};

// Sole heights (file units) of both feet in a posed frame.
std::array<double, 2> SoleHeights(const FeetRig& rig, std::span<const Eigen::Vector3d> world_positions,
                                  std::span<const Eigen::Matrix3d> world_rotations);

// The level a clip's feet stand at, in metres: the 5th percentile of both
// soles' heights over (at most `max_frames`, evenly spaced) frames of the
// clips, which must have the rig's skeleton. 0 when there are no frames.
StatusOr<double> EstimateGroundHeight(std::span<const Clip* const> clips, const FeetRig& rig,
                                      double meters_per_unit, int max_frames = 2000);

// Measures both feet over the clip and detects contacts (see above) from
// params.ground_height_m.
StatusOr<FeetTrack> AnalyzeFeet(const Clip& clip, const FeetRig& rig, const FootContactParams& params);

// ---------------------------------------------------------------------------
// Two-bone IK. Positions are world positions of hip, knee and ankle; the
// rotations are the hip's and knee's world rotations. Returns world rotations
// for hip and knee that put the ankle at `target` (or, out of reach, at the
// reachable point nearest to it on the hip → target line). `bend_hint` is a
// direction the knee should point to (e.g. the toes): the knee bends in the
// plane of the leg and the hint when the leg is straight (under 1.5°) or bent
// away from the hint, in its own bending plane when bent over 4.5° towards the
// hint's side, and in a plane blended between the two otherwise, so that the
// knee moves continuously as the source leg passes between these cases.
struct TwoBoneIkResult {
  Eigen::Matrix3d hip_rotation;   // new world rotation of the hip joint
  Eigen::Matrix3d knee_rotation;  // new world rotation of the knee joint
  Eigen::Vector3d ankle;          // where the ankle ends up
  bool reached = false;           // the target was within reach
};
TwoBoneIkResult SolveTwoBoneIk(const Eigen::Vector3d& hip, const Eigen::Vector3d& knee,
                               const Eigen::Vector3d& ankle, const Eigen::Matrix3d& hip_rotation,
                               const Eigen::Matrix3d& knee_rotation, const Eigen::Vector3d& target,
                               const Eigen::Vector3d& bend_hint);

// ---------------------------------------------------------------------------
struct FootPlantParams {
  bool enabled = true;          // callers' switch: off = frames pass unchanged
  FootContactParams contact;    // detection (ground_height_m: see EstimateGroundHeight)
  double floor_height_m = 0;    // contacts are put on y = this
  double blend_s = 0.2;         // lock release and floor fade-in
  double max_foot_twist_deg = 20;   // a locked foot pivots along beyond this
  // A foot planted only because its lift is not a step (release_distance_m)
  // pivots along beyond this instead, when it is larger (0 = as any locked
  // foot): it stays flatter, as a foot does whose weight shifts off it,
  // instead of rocking onto its toes or heel with the lifted animation.
  // The limit moves between the two no faster than twist_rate_deg_s (0 = at
  // once).
  double held_foot_twist_deg = 0;
  double twist_rate_deg_s = 0;
  // A locked foot pivots along (above) no faster than this (0 = at once).
  double max_foot_pivot_deg_s = 0;
  double max_lock_distance_m = 0.15;  // beyond this the foot steps (or, while the other steps, is dragged); 0 = locks hold
  // A lock that has been further than max_lock_distance_m for this long
  // steps (0 = at once).
  double max_lock_dwell_s = 0;
  // A step to where the animation puts the foot: its length, longer when
  // the step is long enough that its peak horizontal speed would exceed
  // release_speed_m_s (when that is set).
  double step_s = 0.3;
  double step_height_m = 0.09;  // and how high the sole rises (above the contact exit height)
  // If > 0, a step's arc rises this much for each metre it travels (a
  // short step shuffles), up to step_height_m.
  double step_height_per_m = 0;
  // A foot the animation lifts out of its contact leaves its lock only when
  // the lock is further than this from the animated foot (0 = whenever the
  // animation lifts it): a weight shift or a step in place is not a step.
  double release_distance_m = 0;
  // A lock that keeps the body more than max_crouch_m under the height the
  // floor asks (the legs short of reach: the knees bend) for max_crouch_s
  // steps to the animated foot, the lock further from it first, when it is
  // further than release_distance_m from it (0 = never): a person whose
  // stance has gone too wide steps rather than stand in a squat.
  double max_crouch_m = 0;
  double max_crouch_s = 0.5;
  // A foot out of its lock moves no faster than this horizontally (0 = no
  // limit): a released lock far from the animated foot was caught up within
  // the last 60 % of the lock's fade.
  double release_speed_m_s = 0;
  // Soft reach: within this distance of full extension, the distance from
  // the hip to the ankle's target is eased towards the leg's length
  // (d' = L − s·e^{−(d − (L − s))/s}), by raising the target (never moving
  // it horizontally, so a locked foot does not slide); 0 = exact targets.
  // Near full extension the knee's place is very sensitive to that distance
  // (0.2 cm more moves it 1 cm), and a planted leg held straight jittered:
  // on held-out BEAT2 speech the knees' mean jerk was 88-138 m/s³ in every
  // method's output, the speaker's 20-31 (docs/feet.md).
  double soft_reach_m = 0;
  // The knee turns about the hip-ankle line (its swivel) no faster than this
  // (m/s at the knee; 0 = no limit). The BEAT2 speaker's knees swivel at up
  // to 0.5-0.8 m/s; a planted leg whose source knee swung between two
  // segments' directions jumped 20 cm in a frame (6.5 m/s, random segments
  // on held-out speech).
  double max_knee_swivel_m_s = 0;
  // The root is kept this far under the height at which a locked leg would
  // be straight (the reach limit), so that the limit's frame-only drop
  // rarely acts. A person stands on nearly straight legs: 3 cm (until
  // 2026-12-06) bent the standing knee of BEAT2 speech from 15 to 32 degrees,
  // a crouch (docs/feet.md, step 2); 1 cm still to 19 in the planner's
  // output, 0.5 cm to 15-16; StandingFootPlantParams keeps 0.3 cm with its
  // soft reach.
  double knee_margin_m = 0.01;
  // A leg still short of its locked foot's target (the animation moves the
  // hips away faster than the lift's spring follows) raises that foot by up
  // to this much (the heel comes up, as a person's does) before the body is
  // lowered for the frame.
  double reach_raise_m = 0;
  // Of two feet in contact, the lower one counts as standing level with the
  // other, up to this much (0 = every contact sole on the floor). A person
  // standing on one leg holds the other relaxed, its foot pointed, and
  // motion capture shows that toe 1.6-2.5 cm (median) lower than the sole
  // of the foot stood on (BEAT2, both takes). Putting it on the floor
  // raised that foot against its hip and bent its knee from the speaker's
  // 21 to 30 degrees (GC, held-out speech); instead the lift follows the
  // foot stood on and the pointed foot's toes turn up about its ankle to the
  // floor (docs/feet.md, step 2).
  double pointed_foot_m = 0;
  // How fast the pointed foot's allowance (how far under the other sole it
  // counts as level) may change, m/s (0 = at once): it follows the other
  // sole, which rises with a foot the animation lifts before its contact
  // ends, and the pointed foot went down with it for a frame.
  double pointed_foot_speed_m_s = 0;
  // The root's vertical correction (floor and reach) and its horizontal one
  // (anchoring) follow their goals through critically damped springs of
  // these angular frequencies (rad/s; 0 = at once): the locked legs absorb
  // the lag, and the goals' frame-to-frame jumps (contacts coming and going,
  // an ankle's own jerk) do not reach the upper body. A spring lags a steady
  // glide by 2v/ω (0.17 m at 1 m/s and 12 rad/s): anchoring follows at once
  // unless the body stands (StandingFootPlantParams).
  double lift_omega = 10;
  double anchor_omega = 0;
  bool anchor_root = true;      // step 1
  bool floor = true;            // step 2 and the vertical part of step 3
};
Status ValidateFootPlantParams(const FootPlantParams& p);

// The planter for a person standing and talking (the planner's gesture
// methods): a lock steps on its own only when it has been more than 0.35 m
// from the animated foot for 0.3 s (max_lock_distance_m, max_lock_dwell_s:
// the stance follows the animation's, but not every blend), a foot the animation lifts steps
// only when its lock is further than 0.15 m from the animated foot, a foot
// out of its lock moves no faster than 1.2 m/s (release_speed_m_s), a stance
// held only with the body 8 cm low for 0.5 s steps (max_crouch_m,
// max_crouch_s), a step rises 0.2 m per metre it travels, up to 9 cm
// (step_height_per_m), the legs
// ease into straightness over their last 1.5 cm (soft_reach_m), a knee
// swivels no faster than 0.8 m/s (max_knee_swivel_m_s),
// anchoring follows through a 12 rad/s spring, the body stays 0.3 cm
// under the height at which a locked leg is straight (knee_margin_m), a
// pointed foot up to 2 cm lower than the other counts as level with it
// (pointed_foot_m) and a heel comes up to 6 cm (reach_raise_m).
FootPlantParams StandingFootPlantParams();

class FootPlanter {
 public:
  // FAILED_PRECONDITION when the skeleton has no legs (FeetRig::Find) or its
  // root has no X, Y and Z position channels; INVALID_ARGUMENT for params.
  static StatusOr<std::unique_ptr<FootPlanter>> Create(const Skeleton& skeleton,
                                                       const BodyRegionMap& regions,
                                                       double frame_time_s,
                                                       const FootPlantParams& params);

  // Plants the feet in one frame (all channel values, in place), continuing
  // from the frames before. Allocation-free. A frame whose size is not the
  // skeleton's channel count is left unchanged.
  void Apply(std::span<double> frame);

  bool contact(int foot) const { return feet_[static_cast<size_t>(foot)].planted; }
  const FeetRig& rig() const { return rig_; }
  const FootPlantParams& params() const { return p_; }
  int frames() const { return frames_; }

 private:
  FootPlanter(const Skeleton& skeleton, FeetRig rig, double frame_time_s, const FootPlantParams& p);
  // IK of one leg to `target` (animated world), the ankle given its world
  // rotation.
  void SolveLeg(int foot, const Eigen::Vector3d& target, const Eigen::Matrix3d& ankle_rotation,
                std::span<double> frame);
  // Hip-knee plus knee-ankle of a leg as the animation has it this frame.
  double LegLength(size_t foot) const;
  // Turns the solved leg back about its hip-ankle line so that the knee
  // swivels no faster than max_knee_swivel_m_s since the last frame.
  void LimitKneeSwivel(size_t foot, TwoBoneIkResult* ik);

  struct Foot {
    FootContactDetector detector;
    double lock_weight = 0;   // horizontal lock, 1 while in contact
    double floor_weight = 0;  // vertical (sole on the floor)
    Eigen::Vector3d lock = Eigen::Vector3d::Zero();
    Eigen::Quaterniond lock_rotation = Eigen::Quaterniond::Identity();  // the ankle's, world
    Eigen::Vector3d prev_ankle = Eigen::Vector3d::Zero();  // animated, previous frame
    Eigen::Vector3d prev_toe = Eigen::Vector3d::Zero();
    bool planted = false;  // in contact (the detector's, held while a lift is not a step)
    bool held = false;     // planted only because the lift is not a step
    double twist_allow = -1;  // how far the lock may turn from the animated foot now (rad; < 0: not yet set)
    double step = -1;  // progress of a step in [0, 1), -1 = none
    double step_len_s = 0;  // that step's length
    double step_height = 0;  // that step's arc (units)
    double far_s = 0;  // how long the lock has been further than max_lock_distance_m
    Eigen::Vector3d step_from = Eigen::Vector3d::Zero();
    Eigen::Vector2d drawn = Eigen::Vector2d::Zero();  // the horizontal target of the last frame
    bool drawn_limited = false;  // ... held back by release_speed_m_s
    Eigen::Vector3d knee_side = Eigen::Vector3d::Zero();  // the knee's offset from its hip-ankle line, last frame
  };

  Skeleton skeleton_;
  FeetRig rig_;
  FootPlantParams p_;
  double dt_ = 1.0 / 30;
  double units_per_m_ = 100;
  double blend_step_ = 1;
  double max_twist_rad_ = 0;
  double held_twist_rad_ = 0;
  double twist_rate_rad_s_ = 0;
  double pivot_rad_s_ = 0;
  double pointed_speed_units_ = 0;
  double max_lock_units_ = 0;
  std::array<Foot, 2> feet_;
  double release_units_ = 0;
  double soft_units_ = 0;
  double swivel_units_ = 0;
  double knee_margin_units_ = 0;
  double pointed_units_ = 0;
  double reach_raise_units_ = 0;
  Eigen::Vector2d anchor_ = Eigen::Vector2d::Zero();    // root horizontal correction's goal (units)
  Eigen::Vector2d offset_ = Eigen::Vector2d::Zero();    // root horizontal correction (units)
  Eigen::Vector2d offset_v_ = Eigen::Vector2d::Zero();  // its rate (units/s)
  double floor_lift_ = 0;  // the lift that puts the lowest contact sole on the floor (units)
  double lift_ = 0;        // root vertical correction before the reach drop (units)
  double lift_v_ = 0;      // its rate (units/s)
  std::array<double, 2> sink_{};  // the pointed foot's sink shown last frame (units)
  double crouch_s_ = 0;    // how long the reach has held the body max_crouch_m under floor_lift_ (s)
  int frames_ = 0;
  std::vector<Eigen::Vector3d> pos_;
  std::vector<Eigen::Matrix3d> rot_;
  std::vector<int> leg_chain_;    // the rig's joints and their ancestors (the only ones posed)
  std::vector<double> prev_out_;  // previous output frame (Euler references)
};

// Plants the feet of a whole clip in place (the same planter, frame by frame).
Status PlantFeet(Clip* clip, const BodyRegionMap& regions, const FootPlantParams& params);

}  // namespace kinemo::motion
