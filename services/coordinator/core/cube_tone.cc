#include "services/coordinator/core/cube_tone.h"

#include <algorithm>
#include <cmath>
#include <regex>

namespace kinemo::coordinator {
namespace {

constexpr const char* kNeutral = "neutral";

Status Merge(const google::protobuf::Map<std::string, std::string>& in, const std::string& field, CubeToneMap* out) {
  static const std::regex tone_re("^[a-z0-9_-]{1,32}$");
  for (const auto& [key, tone] : in) {
    common::v1::Action a = common::v1::ACTION_UNSPECIFIED;
    if (key == "idle") a = common::v1::ACTION_IDLE;
    if (key == "kisses") a = common::v1::ACTION_KISSES;
    if (key == "shouting") a = common::v1::ACTION_SHOUTING;
    if (a == common::v1::ACTION_UNSPECIFIED)
      return InvalidField(field, "key '", key, "' is not an action (idle, kisses, shouting)");
    if (!std::regex_match(tone, tone_re))
      return InvalidField(kinemo::StrCat(field, "[", key, "]"), "'", tone, "' must match [a-z0-9_-]{1,32}");
    (*out)[a] = tone;
  }
  return absl::OkStatus();
}

}  // namespace

StatusOr<CubeToneMap> MakeCubeToneMap(const google::protobuf::Map<std::string, std::string>& options,
                                      const std::string& options_field,
                                      const google::protobuf::Map<std::string, std::string>& request,
                                      const std::string& request_field) {
  CubeToneMap m = {{common::v1::ACTION_IDLE, kNeutral},
                   {common::v1::ACTION_KISSES, "happy"},
                   {common::v1::ACTION_SHOUTING, "angry"}};
  KINEMO_RETURN_IF_ERROR(Merge(options, options_field, &m));
  KINEMO_RETURN_IF_ERROR(Merge(request, request_field, &m));
  return m;
}

Status ValidateCubeEmphasisGain(double gain, const std::string& field) {
  if (!std::isfinite(gain) || gain < 0 || gain > 1) return InvalidField(field, gain, " must be in [0, 1]");
  return absl::OkStatus();
}

CubeStyle StyleForAction(const CubeToneMap& map, common::v1::Action action, double intensity, double emphasis_gain) {
  CubeStyle out;
  const auto it = map.find(action);
  out.tone = it == map.end() ? kNeutral : it->second;
  if (out.tone == kNeutral) {
    out.weight = 1;
    (*out.style.mutable_tone_weights())[kNeutral] = 1;
    return out;
  }
  const double i = std::isfinite(intensity) ? std::clamp(intensity, -1.0, 1.0) : 0.0;
  out.weight = 0.5 * (1 + i);
  const double gain = std::isfinite(emphasis_gain) ? std::clamp(emphasis_gain, 0.0, 1.0) : 0.0;
  out.emphasis = gain * i;
  if (out.emphasis != 0) out.style.set_gesture_emphasis(out.emphasis);
  (*out.style.mutable_tone_weights())[out.tone] = out.weight;
  if (out.weight < 1) (*out.style.mutable_tone_weights())[kNeutral] = 1 - out.weight;
  return out;
}

}  // namespace kinemo::coordinator
