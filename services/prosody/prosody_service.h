// gRPC adapter of the prosody core (callback API). Errors of the core become
// grpc::Status only here, through ToGrpcStatus.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/audio/decode.h"
#include "common/face/face_compose.h"
#include "common/server/worker_pool.h"
#include "common/status/cancel.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "services/prosody/core/options.h"
#include "services/prosody/core/pipeline.h"

namespace kinemo::prosody {

class SphinxRecognizer;
struct FaceModel;

// The store kind of face models (docs/store.md).
inline constexpr std::string_view kFaceModelsKind = "face_models";
inline constexpr std::string_view kFaceModelFile = "face_model.json";

// ProsodyOptions with its zero fields replaced by the documented defaults.
v1::ProsodyOptions WithDefaults(v1::ProsodyOptions options);

// Request parameters over server defaults over built-in defaults: 0 takes
// the default; a negative, NaN or infinite request value is refused naming
// `field` (e.g. "params.pitch_floor_hz").
StatusOr<AnalysisOptions> ToAnalysisOptions(const v1::AnalysisParams& request,
                                            const v1::AnalysisParams& server_defaults,
                                            std::string_view field = "params");

// The analysis' errors name its options ("pitch.floor_hz: ..."); this names
// the request's fields instead ("params.pitch_floor_hz: ...").
Status ToRequestFields(const Status& status, std::string_view field = "params");

// A track as the API sends it (frames only with `include_frames`).
void FillTrack(const PipelineResult& result, const PipelineRequest& p, bool include_frames,
               v1::ProsodyTrack* track);
// One analysis frame as the API sends it.
void FillFrame(const Frame& f, v1::Frame* out);
// One speech-face frame as the API sends it.
void FillFace(const face::SpeechFaceFrame& f, v1::SpeechFaceFrame* out);
// Analyze's speech face of a whole recording, in two steps (the recording
// may be freed between them): the face features of the mono samples at
// `sample_rate_hz` (resampled to the face model's 16 kHz when needed), then
// the model's offline head over them, with the analysis' recognised phones
// as a second opinion.
StatusOr<std::vector<float>> OfflineSpeechFaceFeatures(std::span<const float> mono, int sample_rate_hz);
std::vector<face::SpeechFaceFrame> OfflineSpeechFace(std::vector<float> features, const FaceModel& model,
                                                     const PipelineResult& result);
// A stream's PCM format: S16LE or F32LE, 8000..96000 Hz, 1 or 2 channels
// (INVALID_ARGUMENT naming `field`.encoding/.sample_rate_hz/.channels).
Status CheckPcmFormat(const common::v1::AudioFormat& format, const std::string& field);
audio::PcmEncoding PcmEncodingOf(common::v1::AudioEncoding encoding);

class ProsodyServiceImpl final : public v1::ProsodyService::CallbackService {
 public:
  explicit ProsodyServiceImpl(const v1::ProsodyOptions& options);
  ~ProsodyServiceImpl() override;

  grpc::ServerUnaryReactor* Analyze(grpc::CallbackServerContext* context,
                                    const v1::AnalyzeRequest* request,
                                    v1::AnalyzeResponse* response) override;
  grpc::ServerBidiReactor<v1::StreamAnalyzeRequest, v1::StreamAnalyzeResponse>* StreamAnalyze(
      grpc::CallbackServerContext* context) override;
  // analyze_chunked.cc.
  grpc::ServerBidiReactor<v1::AnalyzeChunkedRequest, v1::AnalyzeChunkedResponse>* AnalyzeChunked(
      grpc::CallbackServerContext* context) override;

  // Analyze's work on decoded mono samples: the request's parameters and
  // recogniser settings (errors name them under `prefix`, e.g. "config."),
  // `p` filled with the options used. Honours `cancel`.
  StatusOr<PipelineResult> RunAnalysis(std::span<const float> mono, int sample_rate_hz,
                                       const v1::AnalysisParams& params, const v1::RecognizerParams& recognizer,
                                       const CancelToken* cancel, std::string_view prefix, PipelineRequest* p);
  server::WorkerPool& workers() { return *workers_; }
  std::string NextRequestId(const std::string& given);

  const v1::ProsodyOptions& options() const { return options_; }
  std::atomic<int>& active_streams() { return active_streams_; }
  std::atomic<int>& active_chunked() { return active_chunked_; }
  // Null when the recognizer is not built in, disabled, or its models are missing.
  SphinxRecognizer* recognizer() { return recognizer_.get(); }
  // The face model a request names (`field` = its FaceParams field); no id:
  // the bundled one, or null (no face) when there is none. An unknown id:
  // NOT_FOUND (FAILED_PRECONDITION without a store) naming field.model_id;
  // one that is not an id ([a-z0-9_-]{1,64}): INVALID_ARGUMENT naming it.
  StatusOr<std::shared_ptr<const FaceModel>> FaceModelFor(const v1::FaceParams& params,
                                                          std::string_view field) const;

 private:
  v1::ProsodyOptions options_;
  std::unique_ptr<SphinxRecognizer> recognizer_;  // null when not built in or disabled
  // Face models by id (the newest version of each in store_dir), read at start.
  std::map<std::string, std::shared_ptr<const FaceModel>, std::less<>> face_models_;
  std::atomic<int> active_streams_{0};
  std::atomic<int> active_chunked_{0};  // AnalyzeChunked calls
  std::atomic<uint64_t> next_request_id_{1};
  // Runs Analyze calls; declared last, so it drains before the rest goes.
  std::unique_ptr<server::WorkerPool> workers_;
};

}  // namespace kinemo::prosody
