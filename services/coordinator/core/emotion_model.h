// The Vleo -> Pleo emotion model (thesis §5.3): a valence level v in [-1, 1]
// that the Vleo's current action pushes, and the emotion the robot shows,
// derived from v with hysteresis.
//
//   kisses    dv/dt = +rate_per_s × factor(intensity)
//   shouting  dv/dt = -rate_per_s × factor(intensity)
//   idle      dv/dt = 0 (or a decay toward 0 at idle_decay_per_s)
//   factor(i) = min_intensity_factor + (1 - min_intensity_factor) × (i + 1) / 2
//   v is clamped to [-1, 1].
//
// Emotion with hysteresis (enter > exit ≥ 0):
//   neutral -> happy when v ≥ +enter;  happy -> neutral when v ≤ +exit
//   neutral -> angry when v ≤ -enter;  angry -> neutral when v ≥ -exit
// so kisses move angry -> neutral -> happy, shouting happy -> neutral ->
// angry, and idle leaves the emotion where it is.
//
// Initial valence: happy +1, angry -1, neutral 0 (a robot that starts angry
// has been fully angered).
//
// Default rates, chosen against the experiment (thesis §5.3: children took
// 5–40 s, mean 22 s, to make Pleo happy, and similar to make it angry): with
// rate 0.1 /s and enter 0.5, exit 0.3, an angry Pleo (v = -1) under
// sustained kisses becomes neutral at v = -0.3 and happy at v = +0.5, i.e.
// after 1.5 / (0.1 × factor) seconds: 15 s at full intensity (+1), 24 s at
// the cube's middle intensity (0, factor 0.625), 60 s at the lowest (-1,
// factor 0.25). From neutral (v = 0) it takes 5 s at full intensity. Real
// children alternate actions and pauses, which the model integrates, so
// their 22 s mean corresponds to a mix of these.
//
// Time is passed in (monotonic seconds); the model computes the exact time
// of each threshold crossing, so results do not depend on how often it is
// advanced.
#pragma once

#include <limits>
#include <vector>

#include "common/status/status.h"
#include "kinemo/common/v1/vleo.pb.h"
#include "kinemo/coordinator/v1/options.pb.h"

namespace kinemo::coordinator {

using common::v1::Action;
using common::v1::Emotion;

// Resolved parameters (defaults applied, validated).
struct EmotionParams {
  double rate_per_s = 0.1;
  double min_intensity_factor = 0.25;
  double enter_threshold = 0.5;
  double exit_threshold = 0.3;
  double idle_decay_per_s = 0.0;
  double tick_s = 0.05;
  bool intensity_from_valence = false;
};

// Applies the defaults of EmotionModelOptions (zeros) and validates:
// INVALID_ARGUMENT naming the field for negative or non-finite values,
// min_intensity_factor > 1, enter_threshold > 1, exit ≥ enter.
StatusOr<EmotionParams> ResolveEmotionParams(const v1::EmotionModelOptions& options);

// Rate factor of an intensity in [-1, 1].
double IntensityFactor(const EmotionParams& params, double intensity);

// The emotion shown after `previous` at valence v (one hysteresis step; call
// until it stops changing for large jumps).
Emotion NextEmotion(const EmotionParams& params, Emotion previous, double valence);

// Initial valence of an emotion (happy +1, angry -1, else 0).
double InitialValence(Emotion emotion);

struct EmotionChange {
  double time_s = 0.0;  // monotonic time of the crossing
  Emotion from = common::v1::EMOTION_NEUTRAL;
  Emotion to = common::v1::EMOTION_NEUTRAL;
  double valence = 0.0;
  Action action = common::v1::ACTION_IDLE;
  double intensity = 0.0;
};

// One session's model. Not thread-safe (the session manager locks).
class EmotionModel {
 public:
  // `initial` EMOTION_UNSPECIFIED = neutral.
  EmotionModel(const EmotionParams& params, Emotion initial, double time_s);
  // A model in a saved state (valence clamped to [-1, 1]; the emotion is
  // taken as saved, since hysteresis makes it depend on the history), with
  // `action` current from `time_s` on.
  static EmotionModel Restore(const EmotionParams& params, Emotion emotion, double valence,
                              Action action, double intensity, double time_s);

  // Advances to `time_s` (earlier times are ignored) under the current
  // action, appending the emotion changes on the way, in time order.
  void AdvanceTo(double time_s, std::vector<EmotionChange>* changes);
  // Advances to `time_s`, then makes `action` current (intensity clamped to
  // [-1, 1]).
  void SetAction(double time_s, Action action, double intensity,
                 std::vector<EmotionChange>* changes);

  // Monotonic time of the next emotion change if nothing else happens;
  // +infinity if none is coming.
  double NextChangeTime() const;

  double valence() const { return valence_; }
  Emotion emotion() const { return emotion_; }
  Action action() const { return action_; }
  double intensity() const { return intensity_; }
  double time_s() const { return time_s_; }
  // Intensity to command the robot with (see intensity_from_valence).
  double RobotIntensity() const;

 private:
  // Signed valence velocity at the current state (0 if at a limit).
  double Velocity() const;
  // Where the valence would stop under the current action.
  double Limit() const;
  // Next threshold in the direction of motion and the emotion it leads to;
  // false if none.
  bool NextThreshold(double velocity, double* threshold, Emotion* to) const;

  EmotionParams params_;
  Emotion emotion_;
  double valence_;
  Action action_ = common::v1::ACTION_IDLE;
  double intensity_ = 0.0;
  double time_s_;
};

}  // namespace kinemo::coordinator
