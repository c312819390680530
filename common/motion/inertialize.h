// Inertialized transitions between two motions (D. Bollo, "Inertialization:
// High-Performance Animation Transitions in Gears of War", GDC 2018).
//
// At a jump from the motion being shown to a new one, the difference between
// the two — per joint a rotation offset (as a rotation vector, the log of
// R_shown · R_new⁻¹), per position channel a displacement — and its velocity
// and acceleration are read off the last three output frames and the new
// motion's three frames before the jump. Each component of the difference
// then decays to zero over the transition along the quintic that matches its
// value, velocity and acceleration at the start and reaches zero with zero
// velocity and acceleration at the end; the output is the new motion plus the
// difference. So position, velocity and acceleration of every joint stay
// continuous across the jump: a cross-fade's weight curve w(t) adds
// w'''·(b − a) to the jerk and its ends jump in acceleration, while here
// nothing but the two motions' own jerk and the smooth decay remains.
// Unlike Bollo's formulation, which keeps only the velocity toward zero along
// the offset's axis (a growing difference starts its decay at rest), the whole
// velocity and acceleration are kept: dropping them breaks the joint's
// velocity at the jump (on the Gesture Controller's BEAT2 joins the wrists'
// jerk in the two frames after a jump was 300-365 m/s³, 8x the rest).
// The decay may therefore swing past the new pose (the Gesture Controller's
// foot planter takes what reaches the feet). Starting the legs' or the root
// position's decay at rest instead was tried on BEAT2: the unplanted feet
// wandered 15-29 cm from their place, and with the root at rest the wrists
// peaked at 5-11 m/s. The old motion need not be evaluated after the jump,
// and a jump during a transition starts from the frames shown (no held pose).
//
// Per frame, allocation-free after construction; one per stream.
#pragma once

#include <array>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "common/motion/skeleton.h"

namespace kinemo::motion {

class Inertializer {
 public:
  explicit Inertializer(const Skeleton& skeleton);

  // Starts a transition to a new motion lasting `frames` frames (≥ 1).
  // `target_prev` are the new motion's frames before the next one, most
  // recent first (t−1, t−2, t−3; repeat a frame where the motion has none,
  // i.e. at its first frame: it then starts from rest). Without output frames
  // yet, nothing happens (the new motion is shown as it is).
  // With `carry` false every difference starts its decay at rest (as for the
  // joints of StartAtRest). With `carry_frames` (0 = `frames`) shorter than
  // `frames`, the carried velocity and acceleration die out over
  // carry_frames while the difference itself takes `frames`: a long
  // transition (two poses far apart) then does not swing the carried motion
  // further (its swing grows with the length for the velocity, with its
  // square for the acceleration: a 2.4 s decay kicked a BEAT2 leg 1.5 m up).
  void Start(std::span<const double> target_prev1, std::span<const double> target_prev2,
             std::span<const double> target_prev3, int frames, bool carry = true, int carry_frames = 0);

  // Writes the next output frame: `target` (the new motion's frame) plus the
  // decaying difference while a transition runs; `target` as it is after.
  void Apply(std::span<const double> target, std::span<double> out);

  // The listed joints' differences start their decay at rest from now on
  // (their velocity and acceleration are not carried across a jump): where
  // carrying them swings a chain the caller holds some other way, e.g. legs
  // whose feet a planter keeps on the floor. Unknown indices are ignored.
  void StartAtRest(std::span<const int> joints);

  // Replaces the last output frame in the history (what was shown, when the
  // caller changed Apply's output afterwards).
  void SetLastShown(std::span<const double> shown);

  bool active() const { return k_ < frames_; }
  // Frames written since construction.
  int frames_out() const { return count_; }
  // Forgets the output history (the next frame starts a fresh stream).
  void Reset();

 private:
  const Skeleton& skel_;
  std::vector<int> euler_joints_;   // joints with three Euler rotation channels
  std::vector<int> scalar_cols_;    // every other channel (positions, lone rotations)
  std::vector<char> scalar_is_rotation_;
  std::vector<char> euler_at_rest_;   // per euler_joints_ entry (StartAtRest)
  std::vector<char> scalar_at_rest_;  // per scalar_cols_ entry
  // Output history: [0] = t−1, [1] = t−2, [2] = t−3.
  std::array<std::vector<double>, 3> hist_;
  // A difference's value, velocity and acceleration (per frame) at the jump.
  struct Decay {
    double x0 = 0, v0 = 0, a0 = 0;
  };
  std::vector<std::array<Decay, 3>> rd_;  // Euler joints: rotation-vector components
  std::vector<Decay> sd_;                 // scalar columns
  int frames_ = 0, carry_frames_ = 0, k_ = 0, count_ = 0;
};

// Joins of a standing body whose feet something else holds (a foot planter):
// an Inertializer whose legs start their decay at rest and hang from the root
// as if it had too. The root keeps its carried velocity (the whole body turns
// and sways on smoothly), and each hip is turned by what that carried
// velocity adds to the root's rotation, so the legs' world orientation
// decays from rest: a pelvis swing carried into a join otherwise swung both
// legs, lifting both feet at once. `legs`: the leg joints (hips downwards);
// hips are those whose parent is joint 0. Per frame, allocation-free.
class LegsAtRestInertializer {
 public:
  LegsAtRestInertializer(const Skeleton& skeleton, std::span<const int> legs);

  // As Inertializer::Start / Apply.
  void Start(std::span<const double> target_prev1, std::span<const double> target_prev2,
             std::span<const double> target_prev3, int frames, bool carry = true);
  void Apply(std::span<const double> target, std::span<double> out);

 private:
  const Skeleton& skel_;
  Inertializer join_;   // legs at rest
  Inertializer still_;  // legs and root at rest: the root the legs hang from
  std::vector<int> hips_;
  std::vector<double> still_row_;
};

}  // namespace kinemo::motion
