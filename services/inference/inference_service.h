// gRPC adapter of the inference core (callback API). Maps core errors with
// ToGrpcStatus; holds no algorithm code.
#pragma once

#include <atomic>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "common/grpc/artifact_rpcs.h"
#include "common/status/status.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/inference/v1/options.pb.h"
#include "services/inference/core/model_store.h"

namespace kinemo::inference {

class InferenceServiceImpl final : public v1::InferenceService::CallbackService {
 public:
  // Opens the model store (options.store_dir, or its old name model_dir, is
  // required), imports the seed store's models it lacks, loads the newest
  // version of every model (a model that cannot be read is logged and
  // skipped) and the preload_model_ids (which must load).
  static StatusOr<std::shared_ptr<InferenceServiceImpl>> Create(const v1::InferenceOptions& options);

  grpc::ServerWriteReactor<v1::TrainResponse>* Train(grpc::CallbackServerContext* ctx,
                                                     const v1::TrainRequest* request) override;
  grpc::ServerUnaryReactor* Infer(grpc::CallbackServerContext* ctx, const v1::InferRequest* request,
                                  v1::InferResponse* response) override;
  grpc::ServerBidiReactor<v1::StreamInferRequest, v1::StreamInferResponse>* StreamInfer(
      grpc::CallbackServerContext* ctx) override;
  grpc::ServerUnaryReactor* Evaluate(grpc::CallbackServerContext* ctx,
                                     const v1::EvaluateRequest* request,
                                     v1::EvaluateResponse* response) override;
  grpc::ServerUnaryReactor* GetModel(grpc::CallbackServerContext* ctx,
                                     const v1::GetModelRequest* request,
                                     v1::GetModelResponse* response) override;
  grpc::ServerUnaryReactor* ListModels(grpc::CallbackServerContext* ctx,
                                       const v1::ListModelsRequest* request,
                                       v1::ListModelsResponse* response) override;
  grpc::ServerReadReactor<common::v1::PushArtifactRequest>* PushArtifact(
      grpc::CallbackServerContext* ctx, common::v1::PushArtifactResponse* response) override;
  grpc::ServerUnaryReactor* ListArtifacts(grpc::CallbackServerContext* ctx,
                                          const common::v1::ListArtifactsRequest* request,
                                          common::v1::ListArtifactsResponse* response) override;
  grpc::ServerUnaryReactor* DeleteArtifact(grpc::CallbackServerContext* ctx,
                                           const common::v1::DeleteArtifactRequest* request,
                                           common::v1::DeleteArtifactResponse* response) override;

  // Used by the reactors.
  ModelStore& store() { return *store_; }
  const v1::InferenceOptions& options() const { return options_; }
  // Resolves a server-side corpus path under corpus_root.
  StatusOr<std::string> ResolveCorpus(const std::string& relative) const;
  std::atomic<int> trainings{0};
  std::atomic<int> streams{0};

 private:
  explicit InferenceServiceImpl(v1::InferenceOptions options) : options_(std::move(options)) {}
  v1::InferenceOptions options_;
  std::unique_ptr<ModelStore> store_;
  std::shared_ptr<const ArtifactPushHandler> push_;
};

// Proto ↔ core conversions (exposed for tests).
ProsodyStep FromProto(const v1::ProsodyFeatures& f);
StatusOr<PairedSequence> FromProto(const v1::Sequence& s, std::string_view field);

}  // namespace kinemo::inference
