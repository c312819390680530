// Deadlines of the coordinator's calls to the other services, by method
// class (CoordinatorOptions.deadlines, proto/kinemo/coordinator/v1/options.proto):
// short calls, analysis (scaled by the audio's duration), builds, and the
// idle timeout of streams. Plain C++: the adapter sets them on its calls.
#pragma once

#include <string_view>

#include "common/status/status.h"
#include "kinemo/coordinator/v1/options.pb.h"

namespace kinemo::coordinator {

enum class MethodClass { kShort, kAnalysis, kBuild, kStream };

// The class of a kinemo method, by its name ("Analyze", or a full
// "/kinemo.prosody.v1.ProsodyService/Analyze"): builds (Train,
// BuildController, BuildGestureGraph, BuildLocomotionGraph,
// EvaluateLocomotion, LoadLibrary, PushArtifact), analysis (Analyze, Infer,
// Evaluate, Synthesize, SynthesizeGestures, Visemes, PlanTransition),
// streams (StreamAnalyze, StreamInfer, Control, Track, TrackSource, Drive,
// WatchStatus, and the chunked calls of long recordings: AnalyzeChunked,
// SynthesizeChunked, SynthesizeGesturesChunked, VisemesChunked, whose length
// the forwarder cannot see); everything else is short.
MethodClass ClassOfMethod(std::string_view method);

// The resolved deadlines, in seconds (defaults filled in).
struct Deadlines {
  double short_s = 2;
  double analysis_base_s = 10;
  double analysis_per_audio_s = 1;
  double build_s = 3600;
  double stream_idle_s = 10;
  // animate.max_audio_s (0 = 600): the audio of a forwarded analysis call.
  double max_audio_s = 600;

  // INVALID_ARGUMENT naming the field ("deadlines.short_s: ...") for a
  // negative, non-finite or over-a-day value; also checks each
  // services.<svc>.deadline_s.
  static StatusOr<Deadlines> Resolve(const v1::CoordinatorOptions& options);

  // A short call to the service of `endpoint` (its deadline_s when set).
  double Short(const v1::ServiceEndpoint& endpoint) const {
    return endpoint.deadline_s() > 0 ? endpoint.deadline_s() : short_s;
  }
  // An analysis of `audio_s` seconds of audio.
  double Analysis(double audio_s) const { return analysis_base_s + analysis_per_audio_s * audio_s; }
  // A call of class `c` whose audio the caller does not know (forwarded
  // calls); 0 for streams (they keep their caller's deadline).
  double ForClass(MethodClass c) const;
};

}  // namespace kinemo::coordinator
