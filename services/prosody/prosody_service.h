// gRPC adapter of the prosody core (callback API). Errors of the core become
// grpc::Status only here, through ToGrpcStatus.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <string>

#include "common/server/worker_pool.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "services/prosody/core/options.h"

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

class ProsodyServiceImpl final : public v1::ProsodyService::CallbackService {
 public:
  explicit ProsodyServiceImpl(const v1::ProsodyOptions& options);
  ~ProsodyServiceImpl() override;

  grpc::ServerUnaryReactor* Analyze(grpc::CallbackServerContext* context,
                                    const v1::AnalyzeRequest* request,
                                    v1::AnalyzeResponse* response) override;
  grpc::ServerBidiReactor<v1::StreamAnalyzeRequest, v1::StreamAnalyzeResponse>* StreamAnalyze(
      grpc::CallbackServerContext* context) override;

  const v1::ProsodyOptions& options() const { return options_; }
  std::atomic<int>& active_streams() { return active_streams_; }
  // Null when the recognizer is not built in, disabled, or its models are missing.
  SphinxRecognizer* recognizer() { return recognizer_.get(); }
  // The face model a request names (`field` = its FaceParams field); no id:
  // the bundled one, or null (no face) when there is none. An unknown id:
  // NOT_FOUND (FAILED_PRECONDITION without a store) naming field.model_id.
  StatusOr<std::shared_ptr<const FaceModel>> FaceModelFor(const v1::FaceParams& params,
                                                          std::string_view field) const;

 private:
  v1::ProsodyOptions options_;
  std::unique_ptr<SphinxRecognizer> recognizer_;  // null when not built in or disabled
  // Face models by id (the newest version of each in store_dir), read at start.
  std::map<std::string, std::shared_ptr<const FaceModel>, std::less<>> face_models_;
  std::atomic<int> active_streams_{0};
  std::atomic<uint64_t> next_request_id_{1};
  // Runs Analyze calls; declared last, so it drains before the rest goes.
  std::unique_ptr<server::WorkerPool> workers_;
};

}  // namespace kinemo::prosody
