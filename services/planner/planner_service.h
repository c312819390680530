// gRPC adapter of the planner (callback API): the motion library here, and
// each area's RPCs in its own file beside its core:
//   controller/controller_rpcs.cc  BuildController, Synthesize, Control
//   gesture/gesture_rpcs.cc        BuildGestureGraph, SynthesizeGestures, Visemes
//   locomotion/locomotion_rpcs.cc  BuildLocomotionGraph, PlanTransition,
//                                  EvaluateLocomotion, Drive
// RPCs not overridden answer UNIMPLEMENTED. Core errors become grpc::Status
// only through ToGrpcStatus.
#pragma once

#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "common/status/status.h"
#include "kinemo/planner/v1/options.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "services/planner/library/library.h"
// ---- Gesture Controller (controller/controller_rpcs.cc)
#include <atomic>

#include "services/planner/controller/controller.h"
// gesture (GMG/BodySpeech)
#include "services/planner/gesture/graph.h"

namespace kinemo::planner {

class PlannerServiceImpl final : public v1::PlannerService::CallbackService {
 public:
  static StatusOr<std::shared_ptr<PlannerServiceImpl>> Create(const v1::PlannerOptions& options);

  // ---- Motion library (planner_service.cc)
  grpc::ServerUnaryReactor* LoadLibrary(grpc::CallbackServerContext* ctx, const v1::LoadLibraryRequest* request,
                                        v1::LoadLibraryResponse* response) override;

  // ---- Locomotion: Body Part Motion Graphs, AvatAR (locomotion/locomotion_rpcs.cc)
  grpc::ServerUnaryReactor* BuildLocomotionGraph(grpc::CallbackServerContext* ctx,
                                                 const v1::BuildLocomotionGraphRequest* request,
                                                 v1::BuildLocomotionGraphResponse* response) override;
  grpc::ServerUnaryReactor* PlanTransition(grpc::CallbackServerContext* ctx, const v1::PlanTransitionRequest* request,
                                           v1::PlanTransitionResponse* response) override;
  grpc::ServerUnaryReactor* EvaluateLocomotion(grpc::CallbackServerContext* ctx,
                                               const v1::EvaluateLocomotionRequest* request,
                                               v1::EvaluateLocomotionResponse* response) override;
  grpc::ServerBidiReactor<v1::DriveRequest, v1::DriveResponse>* Drive(grpc::CallbackServerContext* ctx) override;
  struct LocomotionState;  // graphs, feature cache, build and stream counters
  static std::shared_ptr<LocomotionState> MakeLocomotionState();
  // ---- end locomotion
  // ---- Gesture Controller (controller/controller_rpcs.cc)
  grpc::ServerWriteReactor<v1::BuildControllerResponse>* BuildController(
      grpc::CallbackServerContext* ctx, const v1::BuildControllerRequest* request) override;
  grpc::ServerUnaryReactor* Synthesize(grpc::CallbackServerContext* ctx, const v1::SynthesizeRequest* request,
                                       v1::SynthesizeResponse* response) override;
  grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse>* Control(grpc::CallbackServerContext* ctx) override;
  struct StoredController {
    int version = 0;
    std::shared_ptr<const controller::Controller> controller;
    v1::ControllerInfo info;
  };
  VersionedStore<StoredController>& controllers() { return controllers_; }
  std::atomic<int> controller_builds{0};
  std::atomic<int> control_streams{0};
  // ---- end Gesture Controller
  // ---- Gesture Motion Graph and BodySpeech (gesture/gesture_rpcs.cc)
  grpc::ServerUnaryReactor* BuildGestureGraph(grpc::CallbackServerContext* ctx,
                                              const v1::BuildGestureGraphRequest* request,
                                              v1::BuildGestureGraphResponse* response) override;
  grpc::ServerUnaryReactor* SynthesizeGestures(grpc::CallbackServerContext* ctx,
                                               const v1::SynthesizeGesturesRequest* request,
                                               v1::SynthesizeGesturesResponse* response) override;
  grpc::ServerUnaryReactor* Visemes(grpc::CallbackServerContext* ctx, const v1::VisemesRequest* request,
                                    v1::VisemesResponse* response) override;
  // BuildGestureGraph without the RPC (also used by PlannerOptions.preload_gesture_graphs).
  Status BuildAndStoreGestureGraph(const v1::BuildGestureGraphRequest* request,
                                   v1::BuildGestureGraphResponse* response);
  // ---- end gesture

  // Shared by the areas.
  const v1::PlannerOptions& options() const { return options_; }
  LibraryStore& libraries() { return libraries_; }
  // Resolves a server-side path under options.library_root; FAILED_PRECONDITION
  // (naming `field`) when it is outside or no root is configured.
  StatusOr<std::string> ResolvePath(const std::string& relative, std::string_view field) const;
  // Loads (and stores) a library from a request; used by LoadLibrary and preload.
  StatusOr<std::shared_ptr<const Library>> LoadAndStore(const v1::LoadLibraryRequest& request,
                                                        std::vector<std::string>* warnings);

 private:
  explicit PlannerServiceImpl(v1::PlannerOptions options) : options_(std::move(options)) {}
  v1::PlannerOptions options_;
  LibraryStore libraries_;
  // Locomotion (locomotion/locomotion_rpcs.cc).
  std::shared_ptr<LocomotionState> locomotion_ = MakeLocomotionState();
  VersionedStore<StoredController> controllers_;  // Gesture Controller
  // gesture: stored Gesture Motion Graphs.
  gesture::GestureGraphStore gesture_graphs_;
};

// Finishes a unary call with `status` (mapped by ToGrpcStatus).
grpc::ServerUnaryReactor* FinishUnary(grpc::CallbackServerContext* ctx, const Status& status);

// Library description for responses.
void ToProto(const Library& library, v1::LibraryInfo* out);

}  // namespace kinemo::planner
