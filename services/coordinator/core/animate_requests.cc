#include "services/coordinator/core/animate_requests.h"

#include <utility>

#include "common/face/face_proto.h"
#include "services/coordinator/core/animate_plan.h"
#include "services/coordinator/core/face_animate.h"

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

pr::AnalyzeRequest AnalyzeRequestFor(const v1::AnimateRequest& request, v1::Method method,
                                     const std::string& request_id) {
  pr::AnalyzeChunkedConfig c = ProsodyConfigFor(request, method, request_id);
  pr::AnalyzeRequest r;
  *r.mutable_audio() = request.audio();
  *r.mutable_params() = std::move(*c.mutable_params());
  if (c.has_recognizer()) *r.mutable_recognizer() = std::move(*c.mutable_recognizer());
  r.set_request_id(request_id);
  *r.mutable_face() = std::move(*c.mutable_face());
  return r;
}

Status CheckAnimateDuration(const pr::ProsodyTrack& track, const v1::AnimateOptions& options) {
  if (options.max_audio_s() > 0 && track.duration_s() > options.max_audio_s()) {
    return InvalidField("audio", track.duration_s(), " s is longer than ", options.max_audio_s(),
                        " s (animate.max_audio_s); animate longer recordings with "
                        "CoordinatorService.AnimateChunked (kinemo animate does)");
  }
  return absl::OkStatus();
}

Status FinishAnimateResponse(const v1::AnimateRequest& request, const pr::ProsodyTrack& track, v1::Method method,
                             const std::string& request_id, v1::AnimateResponse* response) {
  if (track.face_size() > 0) {
    const auto [expression, weight] = method == v1::METHOD_GESTURE_CONTROLLER
                                          ? ExpressionOfStyle(request.style())
                                          : std::pair<face::Expression, float>{face::Expression::kNeutral, 0.0f};
    KINEMO_ASSIGN_OR_RETURN(face::FaceTrack face,
                            AddFaceToMotion(track, expression, weight, request.gesture_style().face_emphasis(),
                                            response->mutable_motion()));
    face::ToProto(face, response->mutable_face());
  }
  *response->mutable_prosody() = SummarizeProsody(track);
  response->set_method(method);
  response->set_request_id(request_id);
  return absl::OkStatus();
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
