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

// A style for the planner: weight w = (1 + intensity) / 2 (clamped to [0, 1])
// on the action's tone and 1 − w on "neutral" (just {neutral: 1} when the
// tone is neutral or the action unmapped).
struct CubeStyle {
  std::string tone;
  double weight = 1;
  planner::v1::StyleVector style;
};
CubeStyle StyleForAction(const CubeToneMap& map, common::v1::Action action, double intensity);

}  // namespace kinemo::coordinator
