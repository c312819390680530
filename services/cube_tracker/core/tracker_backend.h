// The cube tracker service without its RPCs: the options checked and
// completed (limits' defaults, tracking defaults, cubes, default cube and
// intrinsics, file_root, allowed devices), the cube catalog (the "cubes"
// artifacts), the stream slots (max_concurrent_streams), a TrackSession for a
// TrackConfig, ConfigureCube, and what a pushed cube must be. The gRPC
// adapter (cube_tracker_service.cc) parses, calls this and maps the status.
// Thread-safe.
#pragma once

#include <atomic>
#include <memory>
#include <optional>
#include <string_view>

#include "common/status/status.h"
#include "common/store/artifact_store.h"
#include "kinemo/common/v1/artifact.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.pb.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "services/cube_tracker/core/camera.h"
#include "services/cube_tracker/core/cube_catalog.h"
#include "services/cube_tracker/core/track_session.h"
#include "services/cube_tracker/core/tracker.h"

namespace kinemo::cube {

class TrackerBackend {
 public:
  // Validates the options (cubes, default cube, intrinsics file, params),
  // opens the store (store_dir; without one, an ephemeral store) and loads
  // the stored cubes over the options' ones. Errors name the options' field.
  static StatusOr<std::unique_ptr<TrackerBackend>> Create(const cube_tracker::v1::CubeTrackerOptions& options);

  // The options with their defaults filled in.
  const cube_tracker::v1::CubeTrackerOptions& options() const { return options_; }
  CubeCatalog& catalog() { return *catalog_; }

  // A stream slot (max_concurrent_streams): RESOURCE_EXHAUSTED when none is
  // free. Each acquired slot is released once.
  Status AcquireStream();
  void ReleaseStream();

  // A session for `config` (field names in errors start with `field`).
  StatusOr<std::unique_ptr<TrackSession>> NewSession(const cube_tracker::v1::TrackConfig& config,
                                                     std::string_view field);

  // ConfigureCube: stores the request's model as the next version of its id.
  StatusOr<cube_tracker::v1::ConfigureCubeResponse> Configure(const cube_tracker::v1::ConfigureCubeRequest& request);

  // PushArtifact of a cube: the header names one file, cube.textproto.
  static Status CheckPushHeader(const common::v1::PushArtifactHeader& header);
  // Parses, validates and serves a pushed cube (errors name header.files[0]).
  StatusOr<CubeCatalog::Stored> CommitPushed(store::Draft draft, const common::v1::PushArtifactHeader& header);
  // Deletes one version (0 = every version) of a stored cube.
  StatusOr<std::vector<store::ArtifactMeta>> Delete(std::string_view id, std::uint32_t version);

 private:
  TrackerBackend() = default;

  cube_tracker::v1::CubeTrackerOptions options_;
  TrackerOptions default_params_;
  std::optional<CameraModel> default_camera_;
  std::atomic<int> streams_{0};
  std::unique_ptr<CubeCatalog> catalog_;  // the cube models and the default
};

}  // namespace kinemo::cube
