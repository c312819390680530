// The cube tracker's gRPC adapter (callback API): Track (bidi frame stream),
// TrackSource (server-side capture from a video file or a V4L2 camera) and
// ConfigureCube, over the core in services/cube_tracker/core.
//
// The adapter converts messages to the core's plain types and back, validates
// requests (errors name the field, e.g. "config.camera.fx_px: ..."), and maps
// core errors with ToGrpcStatus. Frames that cannot be used give a
// TrackResponse.frame_error for that frame only; the stream goes on.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <grpcpp/grpcpp.h>

#include "common/status/status.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "common/grpc/artifact_rpcs.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_catalog.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/core/tracker.h"

namespace kinemo::cube_tracker {

// One tracking stream: a core tracker plus what the adapter needs to answer
// frames. Not thread-safe (one per call). Exposed for tests.
class TrackSession {
 public:
  TrackSession(cube::CubeTracker tracker, bool include_details, std::uint32_t max_frame_bytes,
               std::uint32_t max_frame_side_px);

  // Tracks one client frame; on a bad frame fills `response->frame_error`.
  void ProcessFrame(const v1::TrackFrame& frame, v1::TrackResponse* response);
  // Tracks one decoded image (server-side capture).
  void ProcessImage(const cv::Mat& image, std::uint64_t frame, double time_s, v1::TrackResponse* response);

  const cube::CubeTracker& tracker() const { return tracker_; }

 private:
  Status Decode(const v1::TrackFrame& frame, const cv::Mat** image);
  void Fill(std::uint64_t frame, double process_us, v1::TrackResponse* response);

  cube::CubeTracker tracker_;
  bool include_details_;
  std::uint32_t max_frame_bytes_;
  std::uint32_t max_frame_side_px_;
  bool have_frame_ = false;
  std::uint64_t last_frame_ = 0;
  double last_time_s_ = 0;
  cube::CubeState state_;
  cv::Mat scratch_, view_;
};

// The core state and events as the API's messages (frame indices from `frame`).
void StateToProto(const cube::CubeState& state, const cube::CubeModel& model,
                  const std::optional<cube::Pose>& camera_from_surface, bool include_details,
                  std::uint64_t frame, v1::CubeState* out);
void EventToProto(const cube::CubeEvent& event, std::uint64_t frame, v1::CubeEvent* out);
// API params over `defaults` (zeros keep the default) -> core options.
StatusOr<cube::TrackerOptions> TrackerOptionsFromProto(const v1::TrackingParams& params,
                                                       const cube::TrackerOptions& defaults,
                                                       std::string_view field);
StatusOr<cube::CameraModel> CameraFromProto(const v1::CameraIntrinsics& intrinsics, std::string_view field);
// `relative` resolved under `root` (symlinks and ".." resolved); refused when
// it leaves the root. NOT_FOUND when it does not exist.
StatusOr<std::string> ResolveUnderRoot(const std::string& root, const std::string& relative,
                                       std::string_view field);

class CubeTrackerService final : public v1::CubeTrackerService::CallbackService {
 public:
  // Validates the options (cubes, default cube, intrinsics file, params),
  // opens the store (store_dir; without one, an ephemeral store) and loads
  // the stored cubes over the options' ones.
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

  // A session for `config` (field names in errors start with `field`).
  StatusOr<std::unique_ptr<TrackSession>> NewSession(const v1::TrackConfig& config, std::string_view field);
  const v1::CubeTrackerOptions& options() const { return options_; }

  // Stream slots (max_concurrent_streams).
  bool AcquireStream();
  void ReleaseStream();

 private:
  CubeTrackerService() = default;

  v1::CubeTrackerOptions options_;
  cube::TrackerOptions default_params_;
  std::optional<cube::CameraModel> default_camera_;
  std::atomic<int> streams_{0};
  std::unique_ptr<cube::CubeCatalog> catalog_;  // the cube models and the default
  std::shared_ptr<const ArtifactPushHandler> push_;
};

}  // namespace kinemo::cube_tracker
