#include "services/coordinator/core/deadlines.h"

#include <array>
#include <cmath>

namespace kinemo::coordinator {
namespace {

constexpr double kMaxDeadlineS = 86400;  // a day

Status CheckSeconds(double v, std::string_view field) {
  if (!std::isfinite(v) || v < 0 || v > kMaxDeadlineS) {
    return InvalidField(field, v, " must be in [0, ", kMaxDeadlineS, "] seconds (0 = the default)");
  }
  return absl::OkStatus();
}

double Or(double v, double d) { return v > 0 ? v : d; }

}  // namespace

MethodClass ClassOfMethod(std::string_view method) {
  if (const auto slash = method.rfind('/'); slash != std::string_view::npos) method = method.substr(slash + 1);
  static constexpr std::array<std::string_view, 7> kBuilds = {
      "Train", "BuildController", "BuildGestureGraph", "BuildLocomotionGraph", "EvaluateLocomotion",
      "LoadLibrary", "PushArtifact"};
  static constexpr std::array<std::string_view, 7> kAnalysis = {
      "Analyze", "Infer", "Evaluate", "Synthesize", "SynthesizeGestures", "Visemes", "PlanTransition"};
  static constexpr std::array<std::string_view, 11> kStreams = {
      "StreamAnalyze", "StreamInfer", "Control", "Track", "TrackSource", "Drive", "WatchStatus",
      "AnalyzeChunked", "SynthesizeChunked", "SynthesizeGesturesChunked", "VisemesChunked"};
  for (std::string_view m : kBuilds) {
    if (m == method) return MethodClass::kBuild;
  }
  for (std::string_view m : kAnalysis) {
    if (m == method) return MethodClass::kAnalysis;
  }
  for (std::string_view m : kStreams) {
    if (m == method) return MethodClass::kStream;
  }
  return MethodClass::kShort;
}

StatusOr<Deadlines> Deadlines::Resolve(const v1::CoordinatorOptions& options) {
  const v1::DeadlineOptions& d = options.deadlines();
  KINEMO_RETURN_IF_ERROR(CheckSeconds(d.short_s(), "deadlines.short_s"));
  KINEMO_RETURN_IF_ERROR(CheckSeconds(d.analysis_base_s(), "deadlines.analysis_base_s"));
  KINEMO_RETURN_IF_ERROR(CheckSeconds(d.analysis_per_audio_s(), "deadlines.analysis_per_audio_s"));
  KINEMO_RETURN_IF_ERROR(CheckSeconds(d.build_s(), "deadlines.build_s"));
  KINEMO_RETURN_IF_ERROR(CheckSeconds(d.stream_idle_s(), "deadlines.stream_idle_s"));
  const auto& sv = options.services();
  const std::array<std::pair<const v1::ServiceEndpoint*, std::string_view>, 5> endpoints = {{
      {&sv.prosody(), "services.prosody.deadline_s"},
      {&sv.inference(), "services.inference.deadline_s"},
      {&sv.planner(), "services.planner.deadline_s"},
      {&sv.cube_tracker(), "services.cube_tracker.deadline_s"},
      {&sv.robot_bridge(), "services.robot_bridge.deadline_s"},
  }};
  for (const auto& [e, field] : endpoints) KINEMO_RETURN_IF_ERROR(CheckSeconds(e->deadline_s(), field));
  Deadlines out;
  out.short_s = Or(d.short_s(), out.short_s);
  out.analysis_base_s = Or(d.analysis_base_s(), out.analysis_base_s);
  out.analysis_per_audio_s = Or(d.analysis_per_audio_s(), out.analysis_per_audio_s);
  out.build_s = Or(d.build_s(), out.build_s);
  out.stream_idle_s = Or(d.stream_idle_s(), out.stream_idle_s);
  out.max_audio_s = Or(options.animate().max_audio_s(), out.max_audio_s);
  return out;
}

double Deadlines::ForClass(MethodClass c) const {
  switch (c) {
    case MethodClass::kShort:
      return short_s;
    case MethodClass::kAnalysis:
      return Analysis(max_audio_s);
    case MethodClass::kBuild:
      return build_s;
    case MethodClass::kStream:
      return 0;
  }
  return short_s;
}

}  // namespace kinemo::coordinator
