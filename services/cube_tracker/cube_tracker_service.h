// The cube tracker's gRPC adapter (callback API): Track (bidi frame stream),
// TrackSource (server-side capture from a video file or a V4L2 camera),
// ConfigureCube and the artifact RPCs, over the core in
// services/cube_tracker/core (cube::TrackerBackend: options, catalog, stream
// slots, sessions; cube::TrackSession: one stream's frames;
// cube::VideoSource: server-side capture).
//
// The adapter parses requests, calls the core and maps its errors with
// ToGrpcStatus (errors name the field, e.g. "config.camera.fx_px: ...").
// Frames that cannot be used give a TrackResponse.frame_error for that frame
// only; the stream goes on.
#pragma once

#include <memory>

#include <grpcpp/grpcpp.h>

#include "common/grpc/artifact_rpcs.h"
#include "common/status/status.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "services/cube_tracker/core/tracker_backend.h"

namespace kinemo::cube_tracker {

class CubeTrackerService final : public v1::CubeTrackerService::CallbackService {
 public:
  // The core's Create (options, store, stored cubes) and the push handler.
  static StatusOr<std::shared_ptr<CubeTrackerService>> Create(const v1::CubeTrackerOptions& options);

  grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse>* Track(
      grpc::CallbackServerContext* context) override;
  grpc::ServerWriteReactor<v1::TrackResponse>* TrackSource(grpc::CallbackServerContext* context,
                                                           const v1::TrackSourceRequest* request) override;
  grpc::ServerUnaryReactor* ConfigureCube(grpc::CallbackServerContext* context,
                                          const v1::ConfigureCubeRequest* request,
                                          v1::ConfigureCubeResponse* response) override;
  grpc::ServerReadReactor<common::v1::PushArtifactRequest>* PushArtifact(
      grpc::CallbackServerContext* context, common::v1::PushArtifactResponse* response) override;
  grpc::ServerUnaryReactor* ListArtifacts(grpc::CallbackServerContext* context,
                                          const common::v1::ListArtifactsRequest* request,
                                          common::v1::ListArtifactsResponse* response) override;
  grpc::ServerUnaryReactor* DeleteArtifact(grpc::CallbackServerContext* context,
                                           const common::v1::DeleteArtifactRequest* request,
                                           common::v1::DeleteArtifactResponse* response) override;

 private:
  CubeTrackerService() = default;

  std::unique_ptr<cube::TrackerBackend> backend_;
  std::shared_ptr<const ArtifactPushHandler> push_;
};

}  // namespace kinemo::cube_tracker
