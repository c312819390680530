#include "services/cube_tracker/cube_tracker_service.h"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <filesystem>
#include <thread>
#include <utility>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "common/grpc/request_check.h"
#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "common/metrics/metrics.h"

namespace kinemo::cube_tracker {
namespace {

constexpr std::uint32_t kDefaultMaxFrameBytes = 8u << 20;
constexpr std::uint32_t kDefaultMaxFrameSide = 4096;
constexpr std::uint32_t kDefaultMaxStreams = 64;

void SetPose(const cube::Pose& pose, common::v1::Pose* out) {
  out->mutable_position_m()->set_x(pose.t[0]);
  out->mutable_position_m()->set_y(pose.t[1]);
  out->mutable_position_m()->set_z(pose.t[2]);
  // Rotation matrix -> unit quaternion (Shepperd's method).
  const cv::Matx33d& R = pose.R;
  const double tr = R(0, 0) + R(1, 1) + R(2, 2);
  double w, x, y, z;
  if (tr > 0) {
    const double s = std::sqrt(tr + 1.0) * 2;
    w = 0.25 * s;
    x = (R(2, 1) - R(1, 2)) / s;
    y = (R(0, 2) - R(2, 0)) / s;
    z = (R(1, 0) - R(0, 1)) / s;
  } else if (R(0, 0) > R(1, 1) && R(0, 0) > R(2, 2)) {
    const double s = std::sqrt(1.0 + R(0, 0) - R(1, 1) - R(2, 2)) * 2;
    w = (R(2, 1) - R(1, 2)) / s;
    x = 0.25 * s;
    y = (R(0, 1) + R(1, 0)) / s;
    z = (R(0, 2) + R(2, 0)) / s;
  } else if (R(1, 1) > R(2, 2)) {
    const double s = std::sqrt(1.0 + R(1, 1) - R(0, 0) - R(2, 2)) * 2;
    w = (R(0, 2) - R(2, 0)) / s;
    x = (R(0, 1) + R(1, 0)) / s;
    y = 0.25 * s;
    z = (R(1, 2) + R(2, 1)) / s;
  } else {
    const double s = std::sqrt(1.0 + R(2, 2) - R(0, 0) - R(1, 1)) * 2;
    w = (R(1, 0) - R(0, 1)) / s;
    x = (R(0, 2) + R(2, 0)) / s;
    y = (R(1, 2) + R(2, 1)) / s;
    z = 0.25 * s;
  }
  out->mutable_orientation()->set_w(w);
  out->mutable_orientation()->set_x(x);
  out->mutable_orientation()->set_y(y);
  out->mutable_orientation()->set_z(z);
}

StatusOr<cube::Pose> PoseFromProto(const common::v1::Pose& p, std::string_view field) {
  const auto& q = p.orientation();
  const double n = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!(n > 1e-9) || !std::isfinite(n)) return InvalidField(StrCat(field, ".orientation"), "not a rotation");
  const double w = q.w() / n, x = q.x() / n, y = q.y() / n, z = q.z() / n;
  cube::Pose pose;
  pose.R = cv::Matx33d(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),  //
                       2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),  //
                       2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y));
  pose.t = cv::Vec3d(p.position_m().x(), p.position_m().y(), p.position_m().z());
  if (!std::isfinite(pose.t[0] + pose.t[1] + pose.t[2])) {
    return InvalidField(StrCat(field, ".position_m"), "not finite");
  }
  return pose;
}

// Re-prefixes a core error ("lift_height_m: ...") with the API's field path.
std::string Describe(const grpc::CallbackServerContext* context) { return context->peer(); }

}  // namespace

// ---------------------------------------------------------------------------
// Conversions
// ---------------------------------------------------------------------------

void EventToProto(const cube::CubeEvent& e, std::uint64_t frame, v1::CubeEvent* out) {
  out->set_frame(frame);
  out->set_time_s(e.time_s);
  switch (e.type) {
    case cube::EventType::kFaceChanged: {
      auto* f = out->mutable_face_changed();
      f->set_from_face(cube::FaceToProto(e.previous_face));
      f->set_to_face(cube::FaceToProto(e.top_face));
      f->set_action(cube::ActionToProto(e.action));
      break;
    }
    case cube::EventType::kActionLaunched: {
      auto* a = out->mutable_action_launched();
      a->set_action(cube::ActionToProto(e.action));
      a->set_intensity(e.intensity);
      a->set_face(cube::FaceToProto(e.top_face));
      break;
    }
    case cube::EventType::kIntensityChanged:
      out->mutable_intensity_changed()->set_from_intensity(e.previous_intensity);
      out->mutable_intensity_changed()->set_to_intensity(e.intensity);
      break;
    case cube::EventType::kLost:
      out->mutable_lost()->set_last_seen_time_s(e.last_seen_time_s);
      break;
    case cube::EventType::kFound:
      out->mutable_found()->set_top_face(cube::FaceToProto(e.top_face));
      break;
  }
}

void StateToProto(const cube::CubeState& s, const cube::CubeModel& model,
                  const std::optional<cube::Pose>& camera_from_surface, bool include_details,
                  std::uint64_t frame, v1::CubeState* out) {
  out->set_frame(frame);
  out->set_time_s(s.time_s);
  out->set_visible(s.visible);
  out->set_top_face(cube::FaceToProto(s.top_face));
  out->set_action(cube::ActionToProto(s.action));
  out->set_yaw_deg(s.yaw_deg);
  out->set_intensity(s.intensity);
  out->mutable_position_m()->set_x(s.position_m[0]);
  out->mutable_position_m()->set_y(s.position_m[1]);
  out->set_resting(s.resting);
  out->set_lifted(s.lifted);
  out->set_height_m(s.height_m);
  out->set_tilt_deg(s.tilt_deg);
  out->set_markers_used(static_cast<std::uint32_t>(s.markers));
  if (!include_details) return;
  if (s.visible) {
    SetPose(s.camera_from_cube, out->mutable_camera_from_cube());
    if (camera_from_surface) {
      SetPose(camera_from_surface->Inverse() * s.camera_from_cube, out->mutable_surface_from_cube());
    }
  }
  for (int f = 0; f < cube::kNumFaces; ++f) {
    if (s.faces_seen[f]) out->add_markers_seen(static_cast<std::uint32_t>(model.faces[f].marker_id));
  }
  out->set_reprojection_error_px(s.reprojection_px);
}

StatusOr<cube::TrackerOptions> TrackerOptionsFromProto(const v1::TrackingParams& p,
                                                       const cube::TrackerOptions& defaults,
                                                       std::string_view field) {
  cube::TrackerOptions o = defaults;
  auto finite = [&](const char* name, double v) -> Status {
    if (!std::isfinite(v)) return InvalidField(StrCat(field, ".", name), "not finite");
    return absl::OkStatus();
  };
  KINEMO_RETURN_IF_ERROR(finite("turns_full_range", p.turns_full_range()));
  if (p.turns_full_range() < 0) return InvalidField(StrCat(field, ".turns_full_range"), "must be positive");
  if (p.turns_full_range() > 0) {
    if (p.turns_full_range() > 100) return InvalidField(StrCat(field, ".turns_full_range"), "must be <= 100");
    o.intensity_per_turn = 2.0 / p.turns_full_range();
  }
  const std::pair<const char*, std::pair<double, double*>> doubles[] = {
      {"intensity_event_step", {p.intensity_event_step(), &o.intensity_event_step}},
      {"lift_height_m", {p.lift_height_m(), &o.lift_height_m}},
      {"rest_height_m", {p.rest_height_m(), &o.rest_height_m}},
      {"rest_tilt_deg", {p.rest_tilt_deg(), &o.rest_tilt_deg}},
      {"flat_tilt_deg", {p.flat_tilt_deg(), &o.flat_tilt_deg}},
      {"face_switch_margin_deg", {p.face_switch_margin_deg(), &o.face_switch_margin_deg}},
      {"filter_min_cutoff_hz", {p.filter_min_cutoff_hz(), &o.filter_min_cutoff_hz}},
      {"max_speed_mps", {p.max_speed_mps(), &o.max_speed_mps}},
  };
  for (const auto& [name, v] : doubles) {
    KINEMO_RETURN_IF_ERROR(finite(name, v.first));
    if (v.first != 0) *v.second = v.first;
  }
  if (p.lost_after_frames() > 1000) {
    return InvalidField(StrCat(field, ".lost_after_frames"), p.lost_after_frames(), " is over 1000");
  }
  if (p.lost_after_frames() != 0) o.lost_after_frames = static_cast<int>(p.lost_after_frames());
  KINEMO_RETURN_IF_ERROR(UnderField(cube::ValidateTrackerOptions(o), field));
  return o;
}

StatusOr<cube::CameraModel> CameraFromProto(const v1::CameraIntrinsics& c, std::string_view field) {
  cube::CameraModel m;
  if (c.width_px() == 0 || c.width_px() > 16384) {
    return InvalidField(StrCat(field, ".width_px"), c.width_px(), " is not in 1..16384");
  }
  if (c.height_px() == 0 || c.height_px() > 16384) {
    return InvalidField(StrCat(field, ".height_px"), c.height_px(), " is not in 1..16384");
  }
  m.width = static_cast<int>(c.width_px());
  m.height = static_cast<int>(c.height_px());
  // A focal length in pixels: at least 1, at most 10^6 (a field of view of
  // 0.06 degrees across a 1000-pixel image).
  if (!(c.fx_px() >= 1 && c.fx_px() <= 1e6)) {
    return InvalidField(StrCat(field, ".fx_px"), c.fx_px(), " is outside [1, 1e6]");
  }
  if (!(c.fy_px() >= 1 && c.fy_px() <= 1e6)) {
    return InvalidField(StrCat(field, ".fy_px"), c.fy_px(), " is outside [1, 1e6]");
  }
  if (!(c.cx_px() >= 0 && c.cx_px() <= m.width)) {
    return InvalidField(StrCat(field, ".cx_px"), c.cx_px(), " is outside the image");
  }
  if (!(c.cy_px() >= 0 && c.cy_px() <= m.height)) {
    return InvalidField(StrCat(field, ".cy_px"), c.cy_px(), " is outside the image");
  }
  m.K = cv::Matx33d(c.fx_px(), 0, c.cx_px(), 0, c.fy_px(), c.cy_px(), 0, 0, 1);
  const int n = c.distortion_size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    return InvalidField(StrCat(field, ".distortion"), n, " coefficients (OpenCV takes 4, 5, 8, 12 or 14)");
  }
  m.dist = cv::Mat::zeros(1, std::max(n, 5), CV_64F);
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(c.distortion(i))) return InvalidField(StrCat(field, ".distortion"), "not finite");
    m.dist.at<double>(0, i) = c.distortion(i);
  }
  KINEMO_RETURN_IF_ERROR(UnderField(cube::ValidateCameraModel(m), field));
  return m;
}

StatusOr<std::string> ResolveUnderRoot(const std::string& root, const std::string& relative,
                                       std::string_view field) {
  namespace fs = std::filesystem;
  if (root.empty()) return InvalidField(field, "server-side files are disabled (file_root is not set)");
  if (relative.empty()) return InvalidField(field, "empty path");
  if (relative.find('\0') != std::string::npos) return InvalidField(field, "path holds a NUL byte");
  std::error_code ec;
  const fs::path canonical_root = fs::canonical(root, ec);
  if (ec) return absl::UnavailableError(StrCat("file_root ", root, ": ", ec.message()));
  const fs::path joined = fs::path(relative).is_absolute() ? fs::path(relative) : canonical_root / relative;
  const fs::path resolved = fs::weakly_canonical(joined, ec);
  if (ec) return InvalidField(field, "'", relative, "': ", ec.message());
  const std::string r = resolved.string(), base = canonical_root.string() + "/";
  if (r.compare(0, base.size(), base) != 0) {
    return InvalidField(field, "'", relative, "' is outside the server's file_root");
  }
  if (!fs::is_regular_file(resolved, ec)) return absl::NotFoundError(StrCat(field, ": '", relative, "' not found"));
  return r;
}

// ---------------------------------------------------------------------------
// TrackSession
// ---------------------------------------------------------------------------

TrackSession::TrackSession(cube::CubeTracker tracker, bool include_details, std::uint32_t max_frame_bytes,
                           std::uint32_t max_frame_side_px)
    : tracker_(std::move(tracker)),
      include_details_(include_details),
      max_frame_bytes_(max_frame_bytes),
      max_frame_side_px_(max_frame_side_px) {}

Status TrackSession::Decode(const v1::TrackFrame& frame, const cv::Mat** image) {
  const v1::Image& img = frame.image();
  const std::string& data = img.data();
  if (data.empty()) return InvalidField("frame.image.data", "empty");
  if (data.size() > max_frame_bytes_) {
    return InvalidField("frame.image.data", data.size(), " bytes is over the limit of ", max_frame_bytes_);
  }
  if (img.width_px() > max_frame_side_px_ || img.height_px() > max_frame_side_px_) {
    return InvalidField("frame.image.width_px", img.width_px(), "x", img.height_px(), " is over the limit of ",
                        max_frame_side_px_, " px");
  }
  const cube::CameraModel& cam = tracker_.camera();
  if ((img.width_px() != 0 && static_cast<int>(img.width_px()) != cam.width) ||
      (img.height_px() != 0 && static_cast<int>(img.height_px()) != cam.height)) {
    return InvalidField("frame.image.width_px", img.width_px(), "x", img.height_px(),
                        " does not match the intrinsics' ", cam.width, "x", cam.height);
  }
  int channels = 0;
  switch (img.encoding()) {
    case v1::IMAGE_ENCODING_JPEG:
    case v1::IMAGE_ENCODING_PNG:
      *image = nullptr;  // decoded by the core
      return absl::OkStatus();
    case v1::IMAGE_ENCODING_GRAY8:
      channels = 1;
      break;
    case v1::IMAGE_ENCODING_BGR8:
    case v1::IMAGE_ENCODING_RGB8:
      channels = 3;
      break;
    default:
      return InvalidField("frame.image.encoding", "unspecified or unknown (", static_cast<int>(img.encoding()), ")");
  }
  if (img.width_px() == 0 || img.height_px() == 0) {
    return InvalidField("frame.image.width_px", "required for a raw encoding");
  }
  const std::size_t w = img.width_px(), h = img.height_px(), row = w * static_cast<std::size_t>(channels);
  const std::size_t stride = img.stride_bytes() == 0 ? row : img.stride_bytes();
  if (stride < row) return InvalidField("frame.image.stride_bytes", stride, " is less than a row (", row, ")");
  if (data.size() < stride * (h - 1) + row) {
    return InvalidField("frame.image.data", data.size(), " bytes do not make a ", w, "x", h, "x", channels,
                        " image with rows of ", stride, " bytes");
  }
  try {
    view_ = cv::Mat(static_cast<int>(h), static_cast<int>(w), channels == 1 ? CV_8UC1 : CV_8UC3,
                    const_cast<char*>(data.data()), stride);
    if (img.encoding() == v1::IMAGE_ENCODING_RGB8) {
      cv::cvtColor(view_, scratch_, cv::COLOR_RGB2GRAY);
      *image = &scratch_;
    } else {
      *image = &view_;
    }
  } catch (const cv::Exception& e) {
    return InvalidField("frame.image", "OpenCV: ", e.what());
  }
  return absl::OkStatus();
}

namespace {

// Frames tracked and their processing time, over every stream of the process
// (rate(kinemo_tracker_frames_total[1m]) = frames/s).
struct TrackerMetrics {
  prometheus::Counter& frames = metrics::Counter(
      "kinemo_tracker_frames_total", "Camera frames the cube tracker processed successfully.");
  prometheus::Histogram& seconds = metrics::Histogram(
      "kinemo_tracker_frame_seconds", "Processing time of one camera frame.",
      {0.001, 0.0025, 0.005, 0.01, 0.02, 0.033, 0.05, 0.1, 0.25});
};
TrackerMetrics& Tracked() {
  static auto* m = new TrackerMetrics();
  return *m;
}

}  // namespace

void TrackSession::Fill(std::uint64_t frame, double process_us, v1::TrackResponse* response) {
  Tracked().frames.Increment();
  Tracked().seconds.Observe(process_us * 1e-6);
  StateToProto(state_, tracker_.model(), tracker_.surface(), include_details_, frame, response->mutable_state());
  for (const cube::CubeEvent& e : state_.events) EventToProto(e, frame, response->add_events());
  response->set_process_us(process_us);
}

void TrackSession::ProcessFrame(const v1::TrackFrame& frame, v1::TrackResponse* response) {
  const auto start = std::chrono::steady_clock::now();
  Status s;
  if (have_frame_ && frame.frame() <= last_frame_) {
    s = InvalidField("frame.frame", frame.frame(), " is not after the previous frame ", last_frame_);
  } else if (!std::isfinite(frame.time_s()) || (have_frame_ && frame.time_s() < last_time_s_)) {
    s = InvalidField("frame.time_s", frame.time_s(), " is not finite or goes back in time");
  }
  const cv::Mat* image = nullptr;
  if (s.ok()) s = Decode(frame, &image);
  if (s.ok()) {
    if (image == nullptr) {
      const std::string& data = frame.image().data();
      s = tracker_.ProcessEncoded(
          std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(data.data()), data.size()),
          frame.time_s(), &state_);
    } else {
      s = tracker_.Process(*image, frame.time_s(), &state_);
    }
  }
  const double us =
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count();
  if (!s.ok()) {
    response->mutable_frame_error()->set_frame(frame.frame());
    response->mutable_frame_error()->set_message(std::string(s.message()));
    response->set_process_us(us);
    return;
  }
  have_frame_ = true;
  last_frame_ = frame.frame();
  last_time_s_ = frame.time_s();
  Fill(frame.frame(), us, response);
}

void TrackSession::ProcessImage(const cv::Mat& image, std::uint64_t frame, double time_s,
                                v1::TrackResponse* response) {
  const auto start = std::chrono::steady_clock::now();
  const Status s = tracker_.Process(image, time_s, &state_);
  const double us =
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count();
  if (!s.ok()) {
    response->mutable_frame_error()->set_frame(frame);
    response->mutable_frame_error()->set_message(std::string(s.message()));
    response->set_process_us(us);
    return;
  }
  Fill(frame, us, response);
}

// ---------------------------------------------------------------------------
// The service
// ---------------------------------------------------------------------------

StatusOr<std::shared_ptr<CubeTrackerService>> CubeTrackerService::Create(const v1::CubeTrackerOptions& options) {
  std::shared_ptr<CubeTrackerService> svc(new CubeTrackerService());
  svc->options_ = options;
  v1::CubeTrackerOptions& o = svc->options_;
  if (o.max_frame_bytes() == 0) o.set_max_frame_bytes(kDefaultMaxFrameBytes);
  if (o.max_frame_side_px() == 0) o.set_max_frame_side_px(kDefaultMaxFrameSide);
  if (o.max_concurrent_streams() == 0) o.set_max_concurrent_streams(kDefaultMaxStreams);
  KINEMO_ASSIGN_OR_RETURN(svc->default_params_, TrackerOptionsFromProto(o.defaults(), {}, "defaults"));
  cube::CubeCatalog::Options co;
  for (int i = 0; i < o.cubes_size(); ++i) {
    auto m = cube::CubeModelFromProto(o.cubes(i));
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
  KINEMO_ASSIGN_OR_RETURN(svc->catalog_, cube::CubeCatalog::Open(co, &skipped));
  for (const auto& why : skipped) log::Warn("cube_unreadable", {{"error", why}});
  auto push = std::make_shared<ArtifactPushHandler>();
  push->store = &svc->catalog_->artifacts();
  push->kinds = {std::string(store::kCubes)};
  push->max_bytes = o.max_artifact_bytes() != 0 ? o.max_artifact_bytes() : kDefaultMaxArtifactBytes;
  push->check_header = [](const common::v1::PushArtifactHeader& h) -> Status {
    if (h.files_size() != 1 || h.files(0).name() != cube::kCubeFileName) {
      return InvalidField("header.files", "a cube is one file named '", cube::kCubeFileName, "'");
    }
    return absl::OkStatus();
  };
  cube::CubeCatalog* catalog = svc->catalog_.get();
  push->commit = [catalog](store::Draft draft,
                           const common::v1::PushArtifactHeader& h) -> StatusOr<common::v1::PushArtifactResponse> {
    KINEMO_ASSIGN_OR_RETURN(cube::CubeCatalog::Stored stored,
                            catalog->CommitPushed(std::move(draft), "header.files[0]", h.overwrite(), h.description()));
    log::Info("cube_pushed", {{"cube_id", stored.meta.id},
                              {"version", static_cast<int>(stored.meta.version)},
                              {"request_id", h.request_id()}});
    common::v1::PushArtifactResponse response;
    *response.mutable_artifact() = ToProto(stored.meta);
    return response;
  };
  svc->push_ = std::move(push);
  if (!o.default_intrinsics_file().empty()) {
    auto cam = cube::LoadCameraModel(o.default_intrinsics_file());
    if (!cam.ok()) return Annotate(cam.status(), "default_intrinsics_file");
    svc->default_camera_ = *cam;
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
  return svc;
}

bool CubeTrackerService::AcquireStream() {
  const int limit = static_cast<int>(options_.max_concurrent_streams());
  int n = streams_.load();
  while (n < limit) {
    if (streams_.compare_exchange_weak(n, n + 1)) return true;
  }
  return false;
}

void CubeTrackerService::ReleaseStream() { streams_.fetch_sub(1); }

StatusOr<std::unique_ptr<TrackSession>> CubeTrackerService::NewSession(const v1::TrackConfig& config,
                                                                      std::string_view field) {
  std::shared_ptr<const cube::CubeModel> model;
  switch (config.cube_case()) {
    case v1::TrackConfig::kCubeModel: {
      auto m = cube::CubeModelFromProto(config.cube_model());
      if (!m.ok()) return UnderField(m.status(), StrCat(field, ".cube_model"));
      model = std::make_shared<const cube::CubeModel>(*m);
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
  cube::CameraModel camera;
  switch (config.intrinsics_case()) {
    case v1::TrackConfig::kCamera: {
      KINEMO_ASSIGN_OR_RETURN(camera, CameraFromProto(config.camera(), StrCat(field, ".camera")));
      break;
    }
    case v1::TrackConfig::kIntrinsicsFile: {
      KINEMO_ASSIGN_OR_RETURN(
          std::string path,
          ResolveUnderRoot(options_.file_root(), config.intrinsics_file(), StrCat(field, ".intrinsics_file")));
      auto cam = cube::LoadCameraModel(path);
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
  KINEMO_ASSIGN_OR_RETURN(cube::TrackerOptions params,
                          TrackerOptionsFromProto(config.params(), default_params_, StrCat(field, ".params")));
  auto tracker = cube::CubeTracker::Create(*model, camera, params);
  if (!tracker.ok()) return UnderField(tracker.status(), field);
  return std::make_unique<TrackSession>(std::move(*tracker), config.include_details(), options_.max_frame_bytes(),
                                        options_.max_frame_side_px());
}

// --- Track: frames from the client -------------------------------------------

namespace {

class TrackReactor final : public grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse> {
 public:
  TrackReactor(CubeTrackerService* service, grpc::CallbackServerContext* context)
      : service_(service), peer_(Describe(context)) {
    if (!service_->AcquireStream()) {
      Finish(grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, "too many streams (max_concurrent_streams)"));
      return;
    }
    acquired_ = true;
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client half-closed (or went away)
      Finish(grpc::Status::OK);
      return;
    }
    switch (request_.message_case()) {
      case v1::TrackRequest::kConfig: {
        if (session_) {
          Finish(ToGrpcStatus(InvalidField("config", "given twice")));
          return;
        }
        // Stream messages pass no request guard (docs/DEVELOPING.md).
        if (Status checked = CheckRequestValues(request_.config(), "config"); !checked.ok()) {
          Finish(ToGrpcStatus(checked));
          return;
        }
        auto session = service_->NewSession(request_.config(), "config");
        if (!session.ok()) {
          log::Info("track_rejected", {{"peer", peer_}, {"error", std::string(session.status().message())}});
          Finish(ToGrpcStatus(session.status()));
          return;
        }
        session_ = std::move(*session);
        log::Info("track_started", {{"peer", peer_}, {"request_id", request_.config().request_id()}});
        StartRead(&request_);
        return;
      }
      case v1::TrackRequest::kFrame:
        if (!session_) {
          Finish(ToGrpcStatus(InvalidField("config", "must be the first message of a Track stream")));
          return;
        }
        response_.Clear();
        session_->ProcessFrame(request_.frame(), &response_);
        StartWrite(&response_);
        return;
      default:
        Finish(ToGrpcStatus(InvalidField("message", "neither config nor frame")));
    }
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "write failed"));
      return;
    }
    StartRead(&request_);
  }

  void OnDone() override {
    if (acquired_) service_->ReleaseStream();
    delete this;
  }

 private:
  CubeTrackerService* service_;
  std::string peer_;
  bool acquired_ = false;
  std::unique_ptr<TrackSession> session_;
  v1::TrackRequest request_;
  v1::TrackResponse response_;
};

// --- TrackSource: frames the server captures ---------------------------------

class SourceReactor final : public grpc::ServerWriteReactor<v1::TrackResponse> {
 public:
  SourceReactor(CubeTrackerService* service, grpc::CallbackServerContext* context,
                const v1::TrackSourceRequest& request)
      : service_(service), request_(request), peer_(Describe(context)) {
    if (!service_->AcquireStream()) {
      Finish(grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, "too many streams (max_concurrent_streams)"));
      return;
    }
    acquired_ = true;
    const Status s = Open();
    if (!s.ok()) {
      log::Info("track_source_rejected", {{"peer", peer_}, {"error", std::string(s.message())}});
      Finish(ToGrpcStatus(s));
      return;
    }
    // The worker's last act is Finish(); OnDone (after it) deletes the reactor.
    std::thread([this] { Run(); }).detach();
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mu_);
    writing_ = false;
    write_failed_ = write_failed_ || !ok;
    cv_.notify_all();
  }

  void OnCancel() override {
    std::lock_guard<std::mutex> lock(mu_);
    cancelled_ = true;
    cv_.notify_all();
  }

  void OnDone() override {
    if (acquired_) service_->ReleaseStream();
    delete this;
  }

 private:
  Status Open() {
    const v1::VideoSource& src = request_.source();
    KINEMO_ASSIGN_OR_RETURN(session_, service_->NewSession(request_.config(), "config"));
    const cube::CameraModel& cam = session_->tracker().camera();
    try {
      switch (src.source_case()) {
        case v1::VideoSource::kVideoFile: {
          KINEMO_ASSIGN_OR_RETURN(std::string path, ResolveUnderRoot(service_->options().file_root(),
                                                                    src.video_file(), "source.video_file"));
          if (!capture_.open(path)) {
            return absl::FailedPreconditionError(
                StrCat("source.video_file: '", src.video_file(), "' cannot be read as video"));
          }
          if (src.start_frame() > 0) capture_.set(cv::CAP_PROP_POS_FRAMES, static_cast<double>(src.start_frame()));
          break;
        }
        case v1::VideoSource::kDevice: {
          bool allowed = false;
          for (const auto& d : service_->options().allowed_devices()) allowed = allowed || d == src.device();
          if (!allowed) return InvalidField("source.device", "'", src.device(), "' is not an allowed device");
          if (!capture_.open(src.device(), cv::CAP_V4L2)) {
            return absl::UnavailableError(StrCat("source.device: '", src.device(), "' cannot be opened"));
          }
          device_ = true;
          if (src.width_px() > 0) capture_.set(cv::CAP_PROP_FRAME_WIDTH, src.width_px());
          if (src.height_px() > 0) capture_.set(cv::CAP_PROP_FRAME_HEIGHT, src.height_px());
          if (src.fps() > 0) capture_.set(cv::CAP_PROP_FPS, src.fps());
          break;
        }
        default:
          return InvalidField("source", "neither video_file nor device");
      }
      const int w = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_WIDTH));
      const int h = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_HEIGHT));
      if (w > 0 && h > 0 && (w != cam.width || h != cam.height)) {
        return InvalidField(device_ ? "source.device" : "source.video_file", "frames are ", w, "x", h,
                            ", the intrinsics are for ", cam.width, "x", cam.height);
      }
      fps_ = capture_.get(cv::CAP_PROP_FPS);
    } catch (const cv::Exception& e) {
      return absl::UnavailableError(StrCat("source: OpenCV: ", e.what()));
    }
    if (!(fps_ > 0 && fps_ < 1000)) fps_ = 30;
    return absl::OkStatus();
  }

  // Waits until the write in flight is done, or until `until` (when given).
  // False if the call is over (cancelled or the write failed).
  bool Wait(std::optional<std::chrono::steady_clock::time_point> until) {
    std::unique_lock<std::mutex> lock(mu_);
    auto done = [this] { return cancelled_ || write_failed_ || !writing_; };
    if (until) {
      cv_.wait_until(lock, *until, [this] { return cancelled_ || write_failed_; });
    } else {
      cv_.wait(lock, done);
    }
    return !cancelled_ && !write_failed_;
  }

  void Run() {
    const v1::VideoSource& src = request_.source();
    const auto start = std::chrono::steady_clock::now();
    grpc::Status final_status = grpc::Status::OK;
    std::uint64_t frame = device_ ? 0 : src.start_frame();
    std::uint64_t sent = 0;
    cv::Mat image;
    while (src.max_frames() == 0 || sent < src.max_frames()) {
      bool ok = false;
      try {
        ok = capture_.read(image);
      } catch (const cv::Exception&) {
        ok = false;
      }
      if (!ok) {
        if (device_) final_status = ToGrpcStatus(absl::UnavailableError("source.device: capture failed"));
        break;
      }
      const double time_s = device_ ? std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()
                                    : static_cast<double>(frame) / fps_;
      if (!device_ && src.realtime()) {
        const auto due = start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                     std::chrono::duration<double>(time_s - src.start_frame() / fps_));
        if (!Wait(due)) break;
      }
      response_.Clear();
      session_->ProcessImage(image, frame, time_s, &response_);
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (cancelled_ || write_failed_) break;
        writing_ = true;
      }
      StartWrite(&response_);
      if (!Wait(std::nullopt)) break;
      ++frame;
      ++sent;
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (cancelled_) final_status = grpc::Status(grpc::StatusCode::CANCELLED, "cancelled");
    }
    log::Info("track_source_done", {{"peer", peer_}, {"frames", static_cast<long long>(sent)}});
    capture_.release();
    Finish(final_status);  // nothing of `this` is touched after this call
  }

  CubeTrackerService* service_;
  const v1::TrackSourceRequest request_;
  std::string peer_;
  bool acquired_ = false;
  std::unique_ptr<TrackSession> session_;
  cv::VideoCapture capture_;
  bool device_ = false;
  double fps_ = 30;
  v1::TrackResponse response_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool writing_ = false;
  bool write_failed_ = false;
  bool cancelled_ = false;
};

}  // namespace

grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse>* CubeTrackerService::Track(
    grpc::CallbackServerContext* context) {
  return new TrackReactor(this, context);
}

grpc::ServerWriteReactor<v1::TrackResponse>* CubeTrackerService::TrackSource(grpc::CallbackServerContext* context,
                                                                            const v1::TrackSourceRequest* request) {
  return new SourceReactor(this, context, *request);
}

grpc::ServerUnaryReactor* CubeTrackerService::ConfigureCube(grpc::CallbackServerContext* context,
                                                            const v1::ConfigureCubeRequest* request,
                                                            v1::ConfigureCubeResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  auto model = cube::CubeModelFromProto(request->model());
  if (!model.ok()) {
    reactor->Finish(ToGrpcStatus(UnderField(model.status(), "model")));
    return reactor;
  }
  auto stored = catalog_->Configure(*model, request->make_default(), request->overwrite());
  if (!stored.ok()) {
    reactor->Finish(ToGrpcStatus(stored.status()));
    return reactor;
  }
  log::Info("cube_configured", {{"cube_id", model->name},
                                {"default", stored->is_default},
                                {"version", static_cast<int>(stored->meta.version)}});
  *response->mutable_model() = cube::CubeModelToProto(*model);
  response->set_is_default(stored->is_default);
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

grpc::ServerReadReactor<common::v1::PushArtifactRequest>* CubeTrackerService::PushArtifact(
    grpc::CallbackServerContext* context, common::v1::PushArtifactResponse* response) {
  return NewArtifactPushReactor(context, response, push_);
}

grpc::ServerUnaryReactor* CubeTrackerService::ListArtifacts(grpc::CallbackServerContext* context,
                                                            const common::v1::ListArtifactsRequest* request,
                                                            common::v1::ListArtifactsResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  Status s = ValidateListRequest(*request, push_->kinds);
  if (s.ok()) {
    auto list = catalog_->List(request->id(), request->all_versions());
    if (list.ok()) {
      AddInfos(*list, response->mutable_artifacts());
      if (catalog_->in_memory()) {
        // Held in memory only: their files are not anywhere a client can use.
        response->set_in_memory(true);
        for (auto& a : *response->mutable_artifacts()) a.clear_files();
      }
    }
    s = list.status();
  }
  reactor->Finish(ToGrpcStatus(s));
  return reactor;
}

grpc::ServerUnaryReactor* CubeTrackerService::DeleteArtifact(grpc::CallbackServerContext* context,
                                                             const common::v1::DeleteArtifactRequest* request,
                                                             common::v1::DeleteArtifactResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  Status s = ValidateDeleteRequest(*request, push_->kinds);
  if (s.ok()) {
    auto removed = catalog_->Delete(request->ref().id(), request->ref().version());
    if (removed.ok()) {
      for (const auto& m : *removed) {
        log::Info("cube_deleted", {{"cube_id", m.id}, {"version", static_cast<int>(m.version)}});
      }
      AddInfos(*removed, response->mutable_deleted());
    }
    s = InRef(removed.status());
  }
  reactor->Finish(ToGrpcStatus(s));
  return reactor;
}

}  // namespace kinemo::cube_tracker
