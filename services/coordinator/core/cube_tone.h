// The cube sets the tone of a talking character (StreamAnimate with a
// session): the session's action picks a tone of the Gesture Controller, and
// the action's intensity (the cube's rotation, in [-1, 1]) blends neutral
// and that tone. Plain C++: no gRPC.
#pragma once

#include <map>
#include <string>

#include <google/protobuf/map.h>

#include "common/status/status.h"
#include "kinemo/common/v1/vleo.pb.h"
#include "kinemo/planner/v1/planner.pb.h"

namespace kinemo::coordinator {

// Action -> tone name.
using CubeToneMap = std::map<common::v1::Action, std::string>;

// The defaults (idle -> neutral, kisses -> happy, shouting -> angry), then
// `options` (CoordinatorOptions animate.cube_tones), then `request`
// (StreamAnimateConfig.cube_tones). Keys are "idle", "kisses", "shouting";
// tones match [a-z0-9_-]{1,32}. INVALID_ARGUMENT naming `options_field` or
// `request_field` otherwise.
StatusOr<CubeToneMap> MakeCubeToneMap(const google::protobuf::Map<std::string, std::string>& options,
                                      const std::string& options_field,
                                      const google::protobuf::Map<std::string, std::string>& request,
                                      const std::string& request_field);

// Gesture emphasis per unit of intensity (CoordinatorOptions
// animate.cube_emphasis_gain, unset = this): the cube's rotation at its
// extremes asks for gestures half as emphasised (or de-emphasised) as the
// Gesture Controller can (e = ±1: every tone's target shifted by one σ of
// its library, planner.v1.StyleVector.gesture_emphasis), so that the tone
// stays the main change and the emphasis a nuance of it (docs/tones.md "Tones and the cube").
inline constexpr double kDefaultCubeEmphasisGain = 0.5;
// The gain must be finite and in [0, 1] (INVALID_ARGUMENT naming `field`).
Status ValidateCubeEmphasisGain(double gain, const std::string& field);

// A style for the planner: weight w = (1 + intensity) / 2 (clamped to [0, 1])
// on the action's tone and 1 − w on "neutral" (just {neutral: 1} when the
// tone is neutral or the action unmapped), and the gesture emphasis
// e = emphasis_gain · intensity (0 for a neutral tone or an unmapped action:
// idle leaves the motion as the speech makes it).
struct CubeStyle {
  std::string tone;
  double weight = 1;
  double emphasis = 0;
  planner::v1::StyleVector style;
};
CubeStyle StyleForAction(const CubeToneMap& map, common::v1::Action action, double intensity,
                         double emphasis_gain = kDefaultCubeEmphasisGain);

}  // namespace kinemo::coordinator
