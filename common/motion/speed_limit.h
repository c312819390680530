// A ceiling on how fast the upper body moves: where a hand, elbow or the head
// moves faster than a limit (e.g. the fastest such motion in the library a
// motion was made from), the rotations of the joints between the pelvis and
// them are smoothed around that moment until it no longer does. For motion
// assembled from a library (blends, time warps), whose joins can add their
// speeds; not for motion capture. Plain C++ (Eigen).
#pragma once

#include <span>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/skeleton.h"
#include "common/status/cancel.h"
#include "common/status/status.h"

namespace kinemo::motion {

struct UpperBodyJoints {
  std::vector<int> measured;  // head, both wrists and elbows
  // Joints with three-axis Euler rotations on the chains from the pelvis to
  // the head and hands, without the joints the legs hang from.
  std::vector<int> smoothed;
  std::vector<int> chain;  // measured with all ancestors, for forward kinematics
};

// FAILED_PRECONDITION when the skeleton has no head or hands (FindKeyJoints).
StatusOr<UpperBodyJoints> FindUpperBodyJoints(const Skeleton& skeleton, const BodyRegionMap& regions);

// The fastest of the measured joints from one frame to the next, m/s.
double MaxUpperBodySpeed(const Clip& clip, const UpperBodyJoints& joints, double meters_per_unit);

struct SpeedLimitParams {
  double max_speed_m_s = 0;       // the ceiling (> 0)
  double meters_per_unit = 0.01;  // the clip's scale
  // Around each frame over the ceiling, the smoothing's weight falls from 1
  // to 0 along a Hann window over this many seconds either side.
  double reach_s = 0.2;
  int max_passes = 40;  // each pass smooths with a [1 2 1] / 4 kernel
  const CancelToken* cancel = nullptr;  // checked before every pass
};

struct SpeedLimitReport {
  double max_before_m_s = 0, max_after_m_s = 0;
  int frames_over_before = 0;  // frames with a measured joint over the ceiling
  int frames_changed = 0;
  int passes = 0;
};

// INVALID_ARGUMENT naming the field for bad params; the token's status when
// cancelled between passes (the clip then holds the passes done). The legs and
// the root are never changed (planted feet stay planted). Each pass touches
// only the frames around those over the ceiling.
StatusOr<SpeedLimitReport> LimitUpperBodySpeed(Clip* clip, const UpperBodyJoints& joints,
                                               const SpeedLimitParams& params);

}  // namespace kinemo::motion
