// The requests of the speech -> animation stages, built from an
// AnimateRequest and the prosody track (plain protos, no gRPC): the stages
// of AnimateChunked, which sends the recording and receives the motion in
// pieces over every hop (coordinator_service.h). They build what Animate's
// stages send.
#pragma once

#include <string>

#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.pb.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "kinemo/inference/v1/inference.pb.h"
#include "kinemo/planner/v1/planner.pb.h"
#include "kinemo/prosody/v1/prosody.pb.h"

namespace kinemo::coordinator {

// The models a request animates with: its own, else the options' defaults.
struct AnimateModelIds {
  std::string inference_model_id, controller_id, gesture_graph_id;
};
// FAILED_PRECONDITION naming `field`.inference_model_id / .controller_id
// (Gesture Controller) or .gesture_graph_id (GMG, BodySpeech) when neither
// the request nor CoordinatorOptions.animate.models names one.
StatusOr<AnimateModelIds> ResolveAnimateModels(const v1::AnimateRequest& request, const v1::AnimateOptions& options,
                                               v1::Method method, std::string_view field);

// The prosody analysis' settings: the request's parameters, the recogniser
// when visemes are asked for (or keywords with the Gesture Controller), the
// speech face (face_model_id, else the bundled model when there is one).
prosody::v1::AnalyzeChunkedConfig ProsodyConfigFor(const v1::AnimateRequest& request, v1::Method method,
                                                   const std::string& request_id);

// Animate's prosody analysis of the whole recording, with ProsodyConfigFor's
// settings.
prosody::v1::AnalyzeRequest AnalyzeRequestFor(const v1::AnimateRequest& request, v1::Method method,
                                              const std::string& request_id);

// INVALID_ARGUMENT "audio: ..." when the track is longer than
// animate.max_audio_s (naming AnimateChunked, which takes longer ones).
Status CheckAnimateDuration(const prosody::v1::ProsodyTrack& track, const v1::AnimateOptions& options);

// The rest of Animate's response once the motion is in it: the face on the
// motion's clock (when the track has a speech face; the SMPL-X jaw follows
// it), the prosody summary, the method and the request id.
Status FinishAnimateResponse(const v1::AnimateRequest& request, const prosody::v1::ProsodyTrack& track,
                             v1::Method method, const std::string& request_id, v1::AnimateResponse* response);

// Inference of the Gesture Controller's beliefs over the track's steps
// (StepsFromProsody). INVALID_ARGUMENT "audio: no speech found" when there
// are none.
StatusOr<inference::v1::InferRequest> InferRequestFor(const prosody::v1::ProsodyTrack& track,
                                                      const std::string& model_id, const std::string& request_id);

// Gesture Controller synthesis from the smoothed beliefs. INTERNAL when
// their count is not the request's step count.
StatusOr<planner::v1::SynthesizeRequest> SynthesizeRequestFor(const v1::AnimateRequest& request,
                                                              const prosody::v1::ProsodyTrack& track,
                                                              const inference::v1::InferRequest& infer,
                                                              const inference::v1::InferResponse& beliefs,
                                                              const std::string& controller_id,
                                                              const std::string& request_id);

// Viseme tracks of the track's phones (Gesture Controller with visemes).
planner::v1::VisemesRequest VisemesRequestFor(const v1::AnimateRequest& request,
                                              const prosody::v1::ProsodyTrack& track);

// GMG / BodySpeech synthesis from the track's accents (and phones, for the
// visemes).
planner::v1::SynthesizeGesturesRequest GesturesRequestFor(const v1::AnimateRequest& request,
                                                          const prosody::v1::ProsodyTrack& track, v1::Method method,
                                                          const std::string& graph_id, const std::string& request_id);

}  // namespace kinemo::coordinator
