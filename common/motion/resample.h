// Resampling a clip to another frame rate.
#pragma once

#include <span>

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::motion {

// Resamples `clip` to `target_fps` frames per second over the same time span:
// output frame k is at time k / target_fps, for every k whose time is within
// the source's span (num_frames − 1) · frame_time_s (with a tolerance of 1 %
// of an output frame, so that e.g. a 0.0333333 s source resampled to 60 and
// back to 30 fps keeps its frame count).
//
// Joints whose rotation channels are three distinct axes are interpolated by
// quaternion slerp of the joint's local rotation, converted back to the
// joint's own Euler order and unwrapped to stay continuous with the previous
// output frame. Other rotation channels (fewer than three, repeated axes) and
// all position channels are interpolated linearly.
StatusOr<Clip> Resample(const Clip& clip, double target_fps);

// One frame between two frames of `skeleton`: f0 + w (f1 − f0), as Resample
// interpolates (slerp for three-axis Euler joints, written in the joint's
// Euler order nearest to `reference`'s angles; linear otherwise). `out` must
// not alias f0, f1 or reference. Allocation-free.
void InterpolateFrame(const Skeleton& skeleton, std::span<const double> f0, std::span<const double> f1, double w,
                      std::span<const double> reference, std::span<double> out);

}  // namespace kinemo::motion
