// A Gesture Controller model pair for in-process tests, made through the
// services' own RPCs: the inference service trains a small remapped CRF on a
// server-side paired corpus, and the planner builds a controller from that
// model's state Gaussians and transition matrix (GetModel with parameters ->
// BuildController, as `kinemo controller build --server` does) over one of
// its libraries.
//
// The corpus is a *synthetic* pairing of real speech and real gesture
// capture (tests/data: LibriVox recordings, Bandai clips placed at the pitch
// accents); they were not recorded together.
#pragma once

#include <chrono>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/status/status.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"

namespace kinemo::coordinator::testing {

// Reads a long build's progress stream to its end: OK if it finished OK and a
// message satisfied `done` (the built artifact).
template <typename Response, typename Reader, typename Done>
Status FinishBuild(Reader& reader, const char* rpc, Done done) {
  Response r;
  bool got = false;
  while (reader->Read(&r)) got = got || done(r);
  const grpc::Status s = reader->Finish();
  if (!s.ok()) return absl::UnknownError(kinemo::StrCat(rpc, ": ", s.error_message()));
  if (!got) return absl::InternalError(kinemo::StrCat(rpc, ": nothing built in the last message"));
  return absl::OkStatus();
}

// Trains `model_id` from `corpus_dir` (relative to the service's
// corpus_root) with a few states, so that it takes seconds.
inline Status TrainModel(inference::v1::InferenceService::Stub* inference, const std::string& model_id,
                         const std::string& corpus_dir) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::minutes(5));
  inference::v1::TrainRequest req;
  req.set_model_id(model_id);
  req.set_corpus_dir(corpus_dir);
  req.mutable_params()->set_num_states(4);
  req.mutable_params()->set_window(2);
  req.mutable_params()->set_num_clusters(3);
  req.mutable_params()->set_hmm_restarts(2);
  req.set_overwrite(true);
  req.set_description("tests/data synthetic pairing (real speech + real gesture clips, not recorded together)");
  auto reader = inference->Train(&ctx, req);
  return FinishBuild<inference::v1::TrainResponse>(reader, "Train",
                                                   [](const auto& r) { return r.has_model(); });
}

// Builds `controller_id` on the planner from inference model `model_id` over
// the planner's library `library_id`.
inline Status BuildController(inference::v1::InferenceService::Stub* inference,
                              planner::v1::PlannerService::Stub* planner, const std::string& model_id,
                              const std::string& controller_id, const std::string& library_id) {
  inference::v1::GetModelResponse model;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    inference::v1::GetModelRequest req;
    req.set_model_id(model_id);
    req.set_include_parameters(true);
    const grpc::Status s = inference->GetModel(&ctx, req, &model);
    if (!s.ok()) return absl::UnknownError(kinemo::StrCat("GetModel: ", s.error_message()));
  }
  planner::v1::BuildControllerRequest req;
  req.set_controller_id(controller_id);
  req.set_library_id(library_id);
  req.set_inference_model_id(model_id);
  req.set_overwrite(true);
  // ModelParameters and StateModel are wire-compatible.
  if (!req.mutable_state_model()->ParseFromString(model.parameters().SerializeAsString())) {
    return absl::InternalError("GetModel: parameters do not parse as a planner StateModel");
  }
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::minutes(5));
  auto reader = planner->BuildController(&ctx, req);
  return FinishBuild<planner::v1::BuildControllerResponse>(reader, "BuildController",
                                                           [](const auto& r) { return r.has_controller(); });
}

}  // namespace kinemo::coordinator::testing
