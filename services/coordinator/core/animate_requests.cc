#include "services/coordinator/core/animate_requests.h"

#include "services/coordinator/core/animate_plan.h"

namespace kinemo::coordinator {

namespace inf = ::kinemo::inference::v1;
namespace pl = ::kinemo::planner::v1;
namespace pr = ::kinemo::prosody::v1;

StatusOr<AnimateModelIds> ResolveAnimateModels(const v1::AnimateRequest& request, const v1::AnimateOptions& options,
                                               v1::Method method, std::string_view field) {
  auto pick = [](const std::string& requested, const std::string& fallback) {
    return requested.empty() ? fallback : requested;
  };
  const auto& dm = options.models();
  const auto& rm = request.models();
  AnimateModelIds ids{pick(rm.inference_model_id(), dm.inference_model_id()),
                      pick(rm.controller_id(), dm.controller_id()),
                      pick(rm.gesture_graph_id(), dm.gesture_graph_id())};
  auto missing = [&](std::string_view name) {
    return absl::FailedPreconditionError(
        kinemo::StrCat(field, ".", name, ": not set, and no default in CoordinatorOptions.animate.models"));
  };
  if (method == v1::METHOD_GESTURE_CONTROLLER) {
    if (ids.inference_model_id.empty()) return missing("inference_model_id");
    if (ids.controller_id.empty()) return missing("controller_id");
  } else if (ids.gesture_graph_id.empty()) {
    return missing("gesture_graph_id");
  }
  return ids;
}

pr::AnalyzeChunkedConfig ProsodyConfigFor(const v1::AnimateRequest& request, v1::Method method,
                                          const std::string& request_id) {
  pr::AnalyzeChunkedConfig c;
  *c.mutable_format() = request.audio().format();
  *c.mutable_params() = request.prosody_params();
  const bool gc = method == v1::METHOD_GESTURE_CONTROLLER;
  if (request.visemes() || (gc && request.keywords_size() > 0)) {
    c.mutable_recognizer()->set_enabled(true);
    if (gc) *c.mutable_recognizer()->mutable_keywords() = request.keywords();
  }
  // The speech face (docs/face.md), as Animate asks Analyze for it.
  c.mutable_face()->set_enabled(true);
  c.mutable_face()->set_model_id(request.face_model_id());
  c.set_name(request.audio().name());
  c.set_request_id(request_id);
  return c;
}

StatusOr<inf::InferRequest> InferRequestFor(const pr::ProsodyTrack& track, const std::string& model_id,
                                            const std::string& request_id) {
  inf::InferRequest r;
  r.set_model_id(model_id);
  for (auto& step : StepsFromProsody(track)) *r.add_inputs() = std::move(step);
  if (r.inputs().empty()) return InvalidField("audio", "no speech found (no prosody steps)");
  r.set_request_id(request_id);
  return r;
}

StatusOr<pl::SynthesizeRequest> SynthesizeRequestFor(const v1::AnimateRequest& request, const pr::ProsodyTrack& track,
                                                     const inf::InferRequest& infer, const inf::InferResponse& beliefs,
                                                     const std::string& controller_id,
                                                     const std::string& request_id) {
  if (beliefs.smoothed_size() != infer.inputs_size()) {
    return absl::InternalError(kinemo::StrCat("inference: ", beliefs.smoothed_size(), " beliefs for ",
                                              infer.inputs_size(), " steps"));
  }
  pl::SynthesizeRequest r;
  r.set_controller_id(controller_id);
  for (const auto& b : beliefs.smoothed()) *r.add_beliefs() = ToBeliefStep(b);
  for (const auto& w : track.words()) {
    if (w.keyword()) *r.add_keywords() = w;
  }
  *r.mutable_style() = request.style();
  r.set_duration_s(track.duration_s());
  r.set_format(request.format());
  r.set_rig_id(request.models().rig_id());
  r.set_request_id(request_id);
  return r;
}

pl::VisemesRequest VisemesRequestFor(const v1::AnimateRequest& request, const pr::ProsodyTrack& track) {
  pl::VisemesRequest r;
  *r.mutable_phones() = track.phones();
  *r.mutable_accents() = track.accents();
  r.set_duration_s(track.duration_s());
  *r.mutable_params() = request.viseme_params();
  if (r.params().face_emphasis() == 0) r.mutable_params()->set_face_emphasis(request.gesture_style().face_emphasis());
  return r;
}

pl::SynthesizeGesturesRequest GesturesRequestFor(const v1::AnimateRequest& request, const pr::ProsodyTrack& track,
                                                 v1::Method method, const std::string& graph_id,
                                                 const std::string& request_id) {
  pl::SynthesizeGesturesRequest r;
  r.set_graph_id(graph_id);
  *r.mutable_accents() = track.accents();
  *r.mutable_phones() = track.phones();
  r.set_duration_s(track.duration_s());
  r.set_algorithm(method == v1::METHOD_GMG ? pl::GESTURE_ALGORITHM_GMG : pl::GESTURE_ALGORITHM_BODYSPEECH);
  *r.mutable_style() = request.gesture_style();
  r.set_include_visemes(request.visemes());
  *r.mutable_viseme_params() = request.viseme_params();
  r.set_format(request.format());
  r.set_rig_id(request.models().rig_id());
  r.set_request_id(request_id);
  return r;
}

}  // namespace kinemo::coordinator
