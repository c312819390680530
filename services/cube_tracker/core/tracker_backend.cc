// The cube tracker service without its RPCs (tracker_backend.h).
#include "services/cube_tracker/core/tracker_backend.h"

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "common/logging/log.h"
#include "services/cube_tracker/core/track_messages.h"
#include "services/cube_tracker/core/video_source.h"

namespace kinemo::cube {
namespace {

namespace v1 = ::kinemo::cube_tracker::v1;

constexpr std::uint32_t kDefaultMaxFrameBytes = 8u << 20;
constexpr std::uint32_t kDefaultMaxFrameSide = 4096;
constexpr std::uint32_t kDefaultMaxStreams = 64;

}  // namespace

StatusOr<std::unique_ptr<TrackerBackend>> TrackerBackend::Create(const v1::CubeTrackerOptions& options) {
  std::unique_ptr<TrackerBackend> backend(new TrackerBackend());
  backend->options_ = options;
  v1::CubeTrackerOptions& o = backend->options_;
  if (o.max_frame_bytes() == 0) o.set_max_frame_bytes(kDefaultMaxFrameBytes);
  if (o.max_frame_side_px() == 0) o.set_max_frame_side_px(kDefaultMaxFrameSide);
  if (o.max_concurrent_streams() == 0) o.set_max_concurrent_streams(kDefaultMaxStreams);
  KINEMO_ASSIGN_OR_RETURN(backend->default_params_, TrackerOptionsFromProto(o.defaults(), {}, "defaults"));
  CubeCatalog::Options co;
  for (int i = 0; i < o.cubes_size(); ++i) {
    auto m = CubeModelFromProto(o.cubes(i));
    if (!m.ok()) return UnderField(m.status(), StrCat("cubes[", i, "]"));
    for (const auto& earlier : co.cubes) {
      if (earlier.name == m->name) {
        return InvalidField(StrCat("cubes[", i, "].cube_id"), "'", m->name, "' is given twice");
      }
    }
    co.cubes.push_back(*std::move(m));
  }
  if (!o.default_cube_id().empty()) {
    bool known = false;
    for (const auto& c : co.cubes) known = known || c.name == o.default_cube_id();
    if (!known) return InvalidField("default_cube_id", "'", o.default_cube_id(), "' is not one of `cubes`");
  }
  co.default_cube_id = o.default_cube_id();
  co.store_dir = o.store_dir();
  co.seed_store_dir = o.seed_store_dir();
  std::vector<std::string> skipped;
  KINEMO_ASSIGN_OR_RETURN(backend->catalog_, CubeCatalog::Open(co, &skipped));
  for (const auto& why : skipped) log::Warn("cube_unreadable", {{"error", why}});
  if (!o.default_intrinsics_file().empty()) {
    auto cam = LoadCameraModel(o.default_intrinsics_file());
    if (!cam.ok()) return Annotate(cam.status(), "default_intrinsics_file");
    backend->default_camera_ = *cam;
  }
  if (!o.file_root().empty()) {
    std::error_code ec;
    if (!std::filesystem::is_directory(o.file_root(), ec)) {
      return InvalidField("file_root", "'", o.file_root(), "' is not a directory");
    }
  }
  for (int i = 0; i < o.allowed_devices_size(); ++i) {
    if (o.allowed_devices(i).rfind("/dev/", 0) != 0) {
      return InvalidField(StrCat("allowed_devices[", i, "]"), "'", o.allowed_devices(i), "' is not under /dev/");
    }
  }
  return backend;
}

Status TrackerBackend::AcquireStream() {
  const int limit = static_cast<int>(options_.max_concurrent_streams());
  int n = streams_.load();
  while (n < limit) {
    if (streams_.compare_exchange_weak(n, n + 1)) return absl::OkStatus();
  }
  return absl::ResourceExhaustedError("too many streams (max_concurrent_streams)");
}

void TrackerBackend::ReleaseStream() { streams_.fetch_sub(1); }

StatusOr<std::unique_ptr<TrackSession>> TrackerBackend::NewSession(const v1::TrackConfig& config,
                                                                      std::string_view field) {
  std::shared_ptr<const CubeModel> model;
  switch (config.cube_case()) {
    case v1::TrackConfig::kCubeModel: {
      auto m = CubeModelFromProto(config.cube_model());
      if (!m.ok()) return UnderField(m.status(), StrCat(field, ".cube_model"));
      model = std::make_shared<const CubeModel>(*m);
      break;
    }
    case v1::TrackConfig::kCubeId: {
      model = catalog_->Find(config.cube_id());
      if (model == nullptr) {
        return absl::NotFoundError(StrCat(field, ".cube_id: '", config.cube_id(), "' is not stored"));
      }
      break;
    }
    default: {
      model = catalog_->Default();
      if (model == nullptr) {
        return InvalidField(StrCat(field, ".cube"), "no cube given and the server has no default cube");
      }
    }
  }
  CameraModel camera;
  switch (config.intrinsics_case()) {
    case v1::TrackConfig::kCamera: {
      KINEMO_ASSIGN_OR_RETURN(camera, CameraFromProto(config.camera(), StrCat(field, ".camera")));
      break;
    }
    case v1::TrackConfig::kIntrinsicsFile: {
      KINEMO_ASSIGN_OR_RETURN(
          std::string path,
          ResolveUnderRoot(options_.file_root(), config.intrinsics_file(), StrCat(field, ".intrinsics_file")));
      auto cam = LoadCameraModel(path);
      if (!cam.ok()) return Annotate(cam.status(), StrCat(field, ".intrinsics_file"));
      camera = *cam;
      break;
    }
    default:
      if (!default_camera_) {
        return InvalidField(StrCat(field, ".intrinsics"), "no intrinsics given and the server has no default");
      }
      camera = *default_camera_;
  }
  if (config.has_surface()) {
    const v1::SurfaceCalibration& sc = config.surface();
    if (sc.has_camera_from_surface()) {
      KINEMO_ASSIGN_OR_RETURN(camera.surface,
                              PoseFromProto(sc.camera_from_surface(), StrCat(field, ".surface.camera_from_surface")));
    } else if (sc.source_case() == v1::SurfaceCalibration::kFromFirstSighting) {
      camera.surface.reset();
    } else {
      return InvalidField(StrCat(field, ".surface"), "set but empty");
    }
  }
  KINEMO_ASSIGN_OR_RETURN(TrackerOptions params,
                          TrackerOptionsFromProto(config.params(), default_params_, StrCat(field, ".params")));
  auto tracker = CubeTracker::Create(*model, camera, params);
  if (!tracker.ok()) return UnderField(tracker.status(), field);
  return std::make_unique<TrackSession>(std::move(*tracker), config.include_details(), options_.max_frame_bytes(),
                                        options_.max_frame_side_px());
}

StatusOr<v1::ConfigureCubeResponse> TrackerBackend::Configure(const v1::ConfigureCubeRequest& request) {
  auto model = CubeModelFromProto(request.model());
  if (!model.ok()) return UnderField(model.status(), "model");
  KINEMO_ASSIGN_OR_RETURN(CubeCatalog::Stored stored,
                          catalog_->Configure(*model, request.make_default(), request.overwrite()));
  log::Info("cube_configured", {{"cube_id", model->name},
                                {"default", stored.is_default},
                                {"version", static_cast<int>(stored.meta.version)}});
  v1::ConfigureCubeResponse response;
  *response.mutable_model() = CubeModelToProto(*model);
  response.set_is_default(stored.is_default);
  return response;
}

Status TrackerBackend::CheckPushHeader(const common::v1::PushArtifactHeader& h) {
  if (h.files_size() != 1 || h.files(0).name() != kCubeFileName) {
    return InvalidField("header.files", "a cube is one file named '", kCubeFileName, "'");
  }
  return absl::OkStatus();
}

StatusOr<CubeCatalog::Stored> TrackerBackend::CommitPushed(store::Draft draft,
                                                           const common::v1::PushArtifactHeader& h) {
  KINEMO_ASSIGN_OR_RETURN(CubeCatalog::Stored stored,
                          catalog_->CommitPushed(std::move(draft), "header.files[0]", h.overwrite(), h.description()));
  log::Info("cube_pushed", {{"cube_id", stored.meta.id},
                            {"version", static_cast<int>(stored.meta.version)},
                            {"request_id", h.request_id()}});
  return stored;
}

StatusOr<std::vector<store::ArtifactMeta>> TrackerBackend::Delete(std::string_view id, std::uint32_t version) {
  KINEMO_ASSIGN_OR_RETURN(std::vector<store::ArtifactMeta> removed, catalog_->Delete(id, version));
  for (const auto& m : removed) {
    log::Info("cube_deleted", {{"cube_id", m.id}, {"version", static_cast<int>(m.version)}});
  }
  return removed;
}

}  // namespace kinemo::cube
