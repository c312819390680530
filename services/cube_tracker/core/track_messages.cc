// The cube tracker core's types as the API's messages and back.
#include "services/cube_tracker/core/track_messages.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace kinemo::cube {
namespace {

namespace v1 = ::kinemo::cube_tracker::v1;

void SetPose(const Pose& pose, common::v1::Pose* out) {
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

}  // namespace

StatusOr<Pose> PoseFromProto(const common::v1::Pose& p, std::string_view field) {
  const auto& q = p.orientation();
  const double n = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!(n > 1e-9) || !std::isfinite(n)) return InvalidField(StrCat(field, ".orientation"), "not a rotation");
  const double w = q.w() / n, x = q.x() / n, y = q.y() / n, z = q.z() / n;
  Pose pose;
  pose.R = cv::Matx33d(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),  //
                       2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),  //
                       2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y));
  pose.t = cv::Vec3d(p.position_m().x(), p.position_m().y(), p.position_m().z());
  if (!std::isfinite(pose.t[0] + pose.t[1] + pose.t[2])) {
    return InvalidField(StrCat(field, ".position_m"), "not finite");
  }
  return pose;
}


void EventToProto(const CubeEvent& e, std::uint64_t frame, v1::CubeEvent* out) {
  out->set_frame(frame);
  out->set_time_s(e.time_s);
  switch (e.type) {
    case EventType::kFaceChanged: {
      auto* f = out->mutable_face_changed();
      f->set_from_face(FaceToProto(e.previous_face));
      f->set_to_face(FaceToProto(e.top_face));
      f->set_action(ActionToProto(e.action));
      break;
    }
    case EventType::kActionLaunched: {
      auto* a = out->mutable_action_launched();
      a->set_action(ActionToProto(e.action));
      a->set_intensity(e.intensity);
      a->set_face(FaceToProto(e.top_face));
      break;
    }
    case EventType::kIntensityChanged:
      out->mutable_intensity_changed()->set_from_intensity(e.previous_intensity);
      out->mutable_intensity_changed()->set_to_intensity(e.intensity);
      break;
    case EventType::kLost:
      out->mutable_lost()->set_last_seen_time_s(e.last_seen_time_s);
      break;
    case EventType::kFound:
      out->mutable_found()->set_top_face(FaceToProto(e.top_face));
      break;
  }
}

void StateToProto(const CubeState& s, const CubeModel& model,
                  const std::optional<Pose>& camera_from_surface, bool include_details,
                  std::uint64_t frame, v1::CubeState* out) {
  out->set_frame(frame);
  out->set_time_s(s.time_s);
  out->set_visible(s.visible);
  out->set_top_face(FaceToProto(s.top_face));
  out->set_action(ActionToProto(s.action));
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
  for (int f = 0; f < kNumFaces; ++f) {
    if (s.faces_seen[f]) out->add_markers_seen(static_cast<std::uint32_t>(model.faces[f].marker_id));
  }
  out->set_reprojection_error_px(s.reprojection_px);
}

StatusOr<TrackerOptions> TrackerOptionsFromProto(const v1::TrackingParams& p,
                                                       const TrackerOptions& defaults,
                                                       std::string_view field) {
  TrackerOptions o = defaults;
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
  KINEMO_RETURN_IF_ERROR(UnderField(ValidateTrackerOptions(o), field));
  return o;
}

StatusOr<CameraModel> CameraFromProto(const v1::CameraIntrinsics& c, std::string_view field) {
  CameraModel m;
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
  KINEMO_RETURN_IF_ERROR(UnderField(ValidateCameraModel(m), field));
  return m;
}

}  // namespace kinemo::cube
