// gRPC adapter of the inference core (callback API). Maps core errors with
// ToGrpcStatus; holds no algorithm code.
#pragma once

#include <atomic>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "common/status/status.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/inference/v1/options.pb.h"
#include "services/inference/core/model_store.h"

namespace kinemo::inference {

class InferenceServiceImpl final : public v1::InferenceService::CallbackService {
 public:
  // Opens the model store (options.model_dir is required) and preloads models.
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
};

// Proto ↔ core conversions (exposed for tests).
ProsodyStep FromProto(const v1::ProsodyFeatures& f);
StatusOr<PairedSequence> FromProto(const v1::Sequence& s, std::string_view field);

}  // namespace kinemo::inference
