// What a tone does to the motion, measured on a generated clip (the cube ->
// tone tests and `kinemo bench tones`): the wrists' mean and p95 world speed
// (common/evaluation MeasureClip), the gesture amplitude, and the Hellinger
// distance between the wrists' speed histogram and a neutral clip's
// (common/evaluation Compare, the neutral clip as the reference).
#pragma once

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::coordinator {

struct ToneMotion {
  double hand_speed_mean_m_s = 0;
  double hand_speed_p95_m_s = 0;
  // RMS over frames and both wrists of the wrist's position relative to the
  // pelvis about its mean over the clip, in metres: how far the hands travel
  // from where they rest.
  double amplitude_m = 0;
  // Hellinger distance of the wrist-speed histograms to `neutral` (0 without one).
  double hellinger_speed_to_neutral = 0;
};

// Metres per unit from the skeleton (the planner's estimate, snapped to a
// standard unit). FAILED_PRECONDITION for a skeleton without wrists, head or feet.
StatusOr<ToneMotion> MeasureToneMotion(const motion::Clip& clip, const motion::Clip* neutral = nullptr);

}  // namespace kinemo::coordinator
