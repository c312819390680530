#include "services/cube_tracker/core/tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"

namespace kinemo::cube {
namespace {

constexpr double kRadToDeg = 180.0 / CV_PI;

double Wrap180(double deg) {
  double w = std::fmod(deg + 180.0, 360.0);
  if (w <= 0) w += 360.0;
  return w - 180.0;
}

}  // namespace

const char* EventTypeName(EventType t) {
  switch (t) {
    case EventType::kFound:
      return "found";
    case EventType::kLost:
      return "lost";
    case EventType::kFaceChanged:
      return "face_changed";
    case EventType::kActionLaunched:
      return "action_launched";
    case EventType::kIntensityChanged:
      return "intensity_changed";
  }
  return "unknown";
}

int TopFace(const cv::Matx33d& R) {
  const cv::Vec3d up_cube = R.t() * cv::Vec3d(0, 0, 1);
  int best = 0;
  double best_dot = -2;
  for (int f = 0; f < kNumFaces; ++f) {
    const double d = FaceFrameOf(f).normal.dot(up_cube);
    if (d > best_dot) {
      best_dot = d;
      best = f;
    }
  }
  return best;
}

double FaceYawDeg(const cv::Matx33d& R, int face) {
  const cv::Vec3d d = R * FaceFrameOf(face).right;
  return std::atan2(d[1], d[0]) * kRadToDeg;
}

Status ValidateTrackerOptions(const TrackerOptions& o) {
  if (!(o.face_switch_margin_deg >= 0 && o.face_switch_margin_deg < 20)) {
    return InvalidField("face_switch_margin_deg", o.face_switch_margin_deg, " is not in [0, 20)");
  }
  if (!(o.rest_height_m > 0 && o.lift_height_m >= o.rest_height_m)) {
    return InvalidField("lift_height_m", "must be >= rest_height_m > 0");
  }
  if (!(o.snap_hold_rms_px >= 0)) return InvalidField("snap_hold_rms_px", "must be >= 0");
  if (!(o.max_speed_mps > 0)) return InvalidField("max_speed_mps", "must be positive");
  if (o.lost_after_frames < 1) return InvalidField("lost_after_frames", o.lost_after_frames, " must be >= 1");
  if (!(o.intensity_per_turn > 0)) return InvalidField("intensity_per_turn", "must be positive");
  if (!(o.intensity_event_step > 0 && o.intensity_event_step <= 2)) {
    return InvalidField("intensity_event_step", "must be in (0, 2]");
  }
  return absl::OkStatus();
}

double CubeTracker::OneEuro::Filter(double value, double dt, double min_cutoff, double beta, double dcutoff) {
  if (!init || min_cutoff <= 0) {
    init = true;
    x = value;
    dx = 0;
    return x;
  }
  auto alpha = [dt](double cutoff) {
    const double tau = 1.0 / (2 * CV_PI * cutoff);
    return 1.0 / (1.0 + tau / dt);
  };
  const double raw_dx = (value - x) / dt;
  dx += alpha(dcutoff) * (raw_dx - dx);
  const double cutoff = min_cutoff + beta * std::abs(dx);
  x += alpha(cutoff) * (value - x);
  return x;
}

StatusOr<CubeTracker> CubeTracker::Create(const CubeModel& model, const CameraModel& camera,
                                          const TrackerOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateTrackerOptions(options));
  KINEMO_ASSIGN_OR_RETURN(CubePoseEstimator est, CubePoseEstimator::Create(model, camera, options.detector));
  return CubeTracker(std::move(est), options, camera);
}

CubeTracker::CubeTracker(CubePoseEstimator estimator, const TrackerOptions& options, const CameraModel& camera)
    : estimator_(std::move(estimator)), options_(options), calibrated_surface_(camera.surface) {
  last_state_.events.reserve(8);
  Reset();
}

void CubeTracker::Reset() {
  surface_ = calibrated_surface_;
  next_frame_ = 0;
  have_pose_ = false;
  last_seen_frame_ = -1;
  visible_ = false;
  ever_seen_ = false;
  missed_ = 0;
  top_face_ = -1;
  last_launched_face_ = -1;
  lifted_ = false;
  resting_ = false;
  yaw_raw_ = 0;
  yaw_deg_ = 0;
  yaw_anchor_ = 0;
  yaw_valid_ = false;
  intensity_ = 0;
  last_event_intensity_ = 0;
  have_time_ = false;
  fx_ = fy_ = fh_ = fyaw_ = OneEuro{};
  velocity_ = cv::Vec3d(0, 0, 0);
  have_jump_ = false;
  last_state_ = CubeState{};
}

void CubeTracker::Emit(EventType t, CubeState* out) {
  CubeEvent e;
  e.type = t;
  e.frame = out->frame;
  e.time_s = out->time_s;
  e.top_face = top_face_;
  e.action = estimator_.model().ActionOfFace(top_face_);
  e.intensity = intensity_;
  e.last_seen_time_s = last_seen_time_s_;
  out->events.push_back(e);
}

namespace {

// Rotation (surface from cube) that stands `face` up, turned by `yaw_rad` about z.
cv::Matx33d StandingRotation(int face, double yaw_rad) {
  const FaceFrame& fr = FaceFrameOf(face);
  // Columns of R^T are the surface axes in the cube frame: z = face normal,
  // x = the face's right axis.
  const cv::Vec3d z = fr.normal, x = fr.right, y = z.cross(x);
  const cv::Matx33d base(x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2]);  // surface_from_cube at yaw 0
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  const cv::Matx33d rz(c, -s, 0, s, c, 0, 0, 0, 1);
  return rz * base;
}

}  // namespace

bool CubeTracker::SnapToSurface(int face, Pose* cfc, double* rms_px) {
  const auto& obj = estimator_.object_points();
  const auto& img = estimator_.image_points();
  if (obj.empty() || !surface_) return false;
  const Pose sfc0 = surface_->Inverse() * *cfc;
  // Parameters: x, y (metres), yaw (radians) of the standing cube.
  double p[3] = {sfc0.t[0], sfc0.t[1], 0};
  {
    const cv::Vec3d d = sfc0.R * FaceFrameOf(face).right;
    p[2] = std::atan2(d[1], d[0]);
  }
  const double half = estimator_.model().cube_size_m / 2;
  const size_t n = obj.size();
  auto residuals = [&](const double* q, std::vector<double>& r) {
    Pose s;
    s.R = StandingRotation(face, q[2]);
    s.t = cv::Vec3d(q[0], q[1], half);
    const Pose c = *surface_ * s;
    cv::projectPoints(obj, c.Rvec(), c.t, estimator_.camera_matrix(), estimator_.distortion(), snap_proj_);
    r.resize(2 * n);
    for (size_t k = 0; k < n; ++k) {
      r[2 * k] = snap_proj_[k].x - img[k].x;
      r[2 * k + 1] = snap_proj_[k].y - img[k].y;
    }
  };
  std::vector<double>& r = snap_r_;
  std::vector<double>& rp = snap_rp_;
  double lambda = 1e-3;
  residuals(p, r);
  double cost = 0;
  for (double v : r) cost += v * v;
  for (int it = 0; it < 15; ++it) {
    // Numeric Jacobian (3 columns).
    double J[3][64 * 2];
    const size_t m = std::min<size_t>(r.size(), 128);
    const double step[3] = {1e-5, 1e-5, 1e-5};
    for (int j = 0; j < 3; ++j) {
      double q[3] = {p[0], p[1], p[2]};
      q[j] += step[j];
      residuals(q, rp);
      for (size_t k = 0; k < m; ++k) J[j][k] = (rp[k] - r[k]) / step[j];
    }
    cv::Matx33d A = cv::Matx33d::zeros();
    cv::Vec3d g(0, 0, 0);
    for (size_t k = 0; k < m; ++k) {
      for (int a = 0; a < 3; ++a) {
        g[a] += J[a][k] * r[k];
        for (int b = 0; b < 3; ++b) A(a, b) += J[a][k] * J[b][k];
      }
    }
    for (int a = 0; a < 3; ++a) A(a, a) *= (1 + lambda);
    const cv::Vec3d delta = A.solve(-g, cv::DECOMP_CHOLESKY);
    const double q[3] = {p[0] + delta[0], p[1] + delta[1], p[2] + delta[2]};
    residuals(q, rp);
    double c2 = 0;
    for (double v : rp) c2 += v * v;
    if (c2 < cost) {
      p[0] = q[0];
      p[1] = q[1];
      p[2] = q[2];
      std::swap(r, rp);
      const bool done = cost - c2 < 1e-10 * (1 + cost);
      cost = c2;
      lambda *= 0.3;
      if (done) break;
    } else {
      lambda *= 10;
      if (lambda > 1e6) break;
    }
  }
  Pose s;
  s.R = StandingRotation(face, p[2]);
  s.t = cv::Vec3d(p[0], p[1], half);
  *cfc = *surface_ * s;
  *rms_px = std::sqrt(cost / n);
  return true;
}

Status CubeTracker::Process(const cv::Mat& frame, double time_s, CubeState* out) {
  const int64_t index = next_frame_++;
  const CameraModel& cam = estimator_.camera();
  if (frame.empty()) return InvalidField("frame", "empty image");
  if (frame.cols != cam.width || frame.rows != cam.height) {
    return InvalidField("frame", frame.cols, "x", frame.rows, " does not match the camera's ", cam.width, "x",
                        cam.height);
  }
  if (frame.depth() != CV_8U || (frame.channels() != 1 && frame.channels() != 3 && frame.channels() != 4)) {
    return InvalidField("frame", "expected 8-bit grey, BGR or BGRA pixels");
  }
  if (!std::isfinite(time_s)) return InvalidField("time_s", "not finite");
  try {
    if (frame.channels() == 1) {
      gray_ = frame;
    } else {
      cv::cvtColor(frame, gray_, frame.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
    }
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("frame: OpenCV: ", e.what()));
  }
  // The prior (search window, disambiguation): the last pose moved on at the
  // last velocity, for as long as the hold-over lasts.
  const bool recent = have_pose_ && index - last_seen_frame_ <= std::max(3, options_.lost_after_frames + 1);
  Pose prior = last_pose_;
  if (recent) prior.t += velocity_ * std::clamp(time_s - last_seen_time_s_, 0.0, 0.5);
  cv::Vec3d up;
  if (surface_) up = surface_->R * cv::Vec3d(0, 0, 1);
  KINEMO_RETURN_IF_ERROR(estimator_.Estimate(gray_, recent ? &prior : nullptr, surface_ ? &up : nullptr, &pose_));
  // A pose further from the prediction than the cube can move is a misdetection
  // (e.g. a marker decoded on a blurred edge) unless the next sighting confirms it.
  if (pose_.found && recent && visible_) {
    const double gap_s = std::max(time_s - last_seen_time_s_, 1e-3);
    const double reach_m = options_.max_speed_mps * gap_s + 0.02;
    if (cv::norm(pose_.camera_from_cube.t - prior.t) > reach_m) {
      const bool confirmed = have_jump_ && cv::norm(pose_.camera_from_cube.t - jump_t_) <= reach_m;
      if (!confirmed) {
        have_jump_ = true;
        jump_t_ = pose_.camera_from_cube.t;
        pose_.found = false;
        ++jumps_rejected_;
      }
    }
  }
  if (pose_.found) have_jump_ = false;
  out->events.clear();
  out->frame = index;
  out->time_s = time_s;
  Update(pose_, time_s, out);
  return absl::OkStatus();
}

void CubeTracker::Update(const PoseResult& pose, double time_s, CubeState* out) {
  double dt = have_time_ ? time_s - last_time_s_ : 1.0 / 30;
  if (!(dt > 1e-6)) dt = 1.0 / 30;
  have_time_ = true;
  last_time_s_ = time_s;

  if (!pose.found) {
    ++missed_;
    if (visible_ && missed_ >= options_.lost_after_frames) {
      visible_ = false;
      Emit(EventType::kLost, out);
    }
    // Everything but visibility holds its last value.
    std::vector<CubeEvent> events = std::move(out->events);
    const int64_t frame = out->frame;
    *out = last_state_;
    out->events = std::move(events);
    out->frame = frame;
    out->time_s = time_s;
    out->visible = false;
    out->markers = 0;
    out->faces_seen = {};
    return;
  }
  missed_ = 0;
  if (!visible_) {
    visible_ = true;
    ever_seen_ = true;
    Emit(EventType::kFound, out);
  }
  if (have_pose_ && out->frame - last_seen_frame_ > 2) {
    // Back after a gap: the filtered position would drag from where the cube was.
    fx_ = fy_ = fh_ = OneEuro{};
  }
  if (have_pose_ && out->frame - last_seen_frame_ <= 2 && time_s > last_seen_time_s_) {
    // Velocity of the cube's centre (camera frame), lightly smoothed.
    const cv::Vec3d v = (pose.camera_from_cube.t - last_pose_.t) / (time_s - last_seen_time_s_);
    velocity_ = 0.5 * velocity_ + 0.5 * v;
  } else {
    velocity_ = cv::Vec3d(0, 0, 0);
  }
  last_pose_ = pose.camera_from_cube;
  have_pose_ = true;
  last_seen_frame_ = out->frame;
  last_seen_time_s_ = time_s;

  const CubeModel& model = estimator_.model();
  const double half = model.cube_size_m / 2;
  if (!surface_) {
    // Assume the cube stands flat: the face most facing image-up is on top.
    const cv::Matx33d& R = pose.camera_from_cube.R;
    int top = 0;
    double best = -2;
    for (int f = 0; f < kNumFaces; ++f) {
      const double d = (R * FaceFrameOf(f).normal).dot(cv::Vec3d(0, -1, 0));
      if (d > best) {
        best = d;
        top = f;
      }
    }
    const cv::Vec3d z = R * FaceFrameOf(top).normal;
    cv::Vec3d x = cv::Vec3d(1, 0, 0) - z * z[0];
    x = x / cv::norm(x);
    const cv::Vec3d y = z.cross(x);
    Pose s;
    s.R = cv::Matx33d(x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2]);
    s.t = pose.camera_from_cube.t - z * half;
    surface_ = s;
  }
  Pose camera_from_cube = pose.camera_from_cube;
  double rms_px = pose.rms_px;
  Pose sfc = surface_->Inverse() * camera_from_cube;
  if (options_.snap_to_surface && pose.markers * 4 <= 128) {
    const int face_now = TopFace(sfc.R);
    const cv::Vec3d n = sfc.R * FaceFrameOf(face_now).normal;
    const double tilt_now = std::acos(std::clamp(n[2], -1.0, 1.0)) * kRadToDeg;
    double lowest = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 8; ++i) {
      const cv::Vec3d c((i & 1) ? half : -half, (i & 2) ? half : -half, (i & 4) ? half : -half);
      lowest = std::min(lowest, sfc.Apply(c)[2]);
    }
    // While the cube was standing on the surface it stays there unless the
    // standing pose stops explaining the corners (motion blur makes a single
    // marker's free pose tilt and lift).
    const bool was_down = top_face_ >= 0 && !lifted_ && face_now == top_face_;
    if (tilt_now < options_.snap_tilt_deg && (lowest < options_.snap_height_m || was_down)) {
      Pose snapped = camera_from_cube;
      double snapped_rms = 0;
      if (SnapToSurface(face_now, &snapped, &snapped_rms) &&
          (snapped_rms <= pose.rms_px * options_.snap_rms_ratio + 0.5 ||
           (was_down && snapped_rms <= options_.snap_hold_rms_px))) {
        camera_from_cube = snapped;
        rms_px = snapped_rms;
        sfc = surface_->Inverse() * camera_from_cube;
      }
    }
  }
  last_pose_ = camera_from_cube;
  const cv::Matx33d& R = sfc.R;

  // Top face with hysteresis.
  const cv::Vec3d up_cube = R.t() * cv::Vec3d(0, 0, 1);
  std::array<double, kNumFaces> angle;
  int best = 0;
  for (int f = 0; f < kNumFaces; ++f) {
    angle[f] = std::acos(std::clamp(FaceFrameOf(f).normal.dot(up_cube), -1.0, 1.0)) * kRadToDeg;
    if (angle[f] < angle[best]) best = f;
  }
  int face = top_face_;
  if (face < 0 || (best != face && angle[best] < angle[face] - 2 * options_.face_switch_margin_deg)) face = best;
  const double tilt = angle[face];

  // Lowest corner above the surface.
  double height = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 8; ++i) {
    const cv::Vec3d c((i & 1) ? half : -half, (i & 2) ? half : -half, (i & 4) ? half : -half);
    height = std::min(height, sfc.Apply(c)[2]);
  }
  const double mc = options_.filter_min_cutoff_hz, dc = options_.filter_dcutoff_hz;
  const double bp = options_.filter_beta_position;
  const double x = fx_.Filter(sfc.t[0], dt, mc, bp, dc);
  const double y = fy_.Filter(sfc.t[1], dt, mc, bp, dc);
  const double h = fh_.Filter(height, dt, mc, bp, dc);

  // Lift / rest.
  if (h > options_.lift_height_m) {
    lifted_ = true;
  } else if (h < options_.rest_height_m && tilt < options_.rest_tilt_deg) {
    lifted_ = false;
  }

  // Yaw, intensity, face changes. The intensity follows turns of the cube
  // standing on the surface (not tilts in the air, which also swing the yaw).
  const double wrapped = FaceYawDeg(R, face);
  const bool flat = tilt < options_.flat_tilt_deg && !lifted_;
  if (face != top_face_) {
    const int previous = top_face_;
    top_face_ = face;
    fyaw_ = OneEuro{};
    yaw_raw_ = wrapped;
    yaw_deg_ = fyaw_.Filter(yaw_raw_, dt, mc, options_.filter_beta_yaw, dc);
    yaw_anchor_ = yaw_deg_;
    yaw_valid_ = flat;
    intensity_ = 0;
    last_event_intensity_ = 0;
    if (previous >= 0) {
      Emit(EventType::kFaceChanged, out);
      out->events.back().previous_face = previous;
    }
  } else {
    yaw_raw_ += Wrap180(wrapped - yaw_raw_);
    yaw_deg_ = fyaw_.Filter(yaw_raw_, dt, mc, options_.filter_beta_yaw, dc);
    if (flat) {
      if (yaw_valid_) {
        // Clockwise seen from above (yaw decreasing) raises the intensity.
        intensity_ = std::clamp(intensity_ - (yaw_deg_ - yaw_anchor_) / 360.0 * options_.intensity_per_turn,
                                -1.0, 1.0);
      }
      yaw_anchor_ = yaw_deg_;
      yaw_valid_ = true;
    } else {
      yaw_valid_ = false;
    }
    const bool at_end = std::abs(intensity_) >= 1.0 && std::abs(last_event_intensity_) < 1.0;
    if (std::abs(intensity_ - last_event_intensity_) >= options_.intensity_event_step - 1e-9 || at_end) {
      const double previous = last_event_intensity_;
      last_event_intensity_ = intensity_;
      Emit(EventType::kIntensityChanged, out);
      out->events.back().previous_intensity = previous;
    }
  }

  // A Found raised above names the top face it was found with.
  for (CubeEvent& e : out->events) {
    if (e.type == EventType::kFound) {
      e.top_face = top_face_;
      e.action = model.ActionOfFace(top_face_);
    }
  }

  // Launches.
  resting_ = !lifted_ && h < options_.rest_height_m && tilt < options_.rest_tilt_deg;
  if (resting_ && top_face_ != last_launched_face_) {
    last_launched_face_ = top_face_;
    Emit(EventType::kActionLaunched, out);
  }

  out->visible = true;
  out->top_face = top_face_;
  out->action = model.ActionOfFace(top_face_);
  out->yaw_deg = yaw_deg_;
  out->intensity = intensity_;
  out->position_m = cv::Vec2d(x, y);
  out->height_m = h;
  out->tilt_deg = tilt;
  out->lifted = lifted_;
  out->resting = resting_;
  out->markers = pose.markers;
  out->faces_seen = pose.face_seen;
  out->reprojection_px = rms_px;
  out->camera_from_cube = camera_from_cube;
  // Keep a copy of the scalars for frames without the cube (no events).
  last_state_.frame = out->frame;
  last_state_.time_s = out->time_s;
  last_state_.visible = true;
  last_state_.top_face = out->top_face;
  last_state_.action = out->action;
  last_state_.yaw_deg = out->yaw_deg;
  last_state_.intensity = out->intensity;
  last_state_.position_m = out->position_m;
  last_state_.height_m = out->height_m;
  last_state_.tilt_deg = out->tilt_deg;
  last_state_.lifted = out->lifted;
  last_state_.resting = out->resting;
  last_state_.markers = out->markers;
  last_state_.reprojection_px = out->reprojection_px;
  last_state_.camera_from_cube = out->camera_from_cube;
}

Status CubeTracker::ProcessEncoded(std::span<const uint8_t> bytes, double time_s, CubeState* out) {
  if (bytes.empty()) {
    ++next_frame_;
    return InvalidField("frame", "no bytes");
  }
  const bool jpeg = bytes.size() >= 2 && bytes[0] == 0xFF && bytes[1] == 0xD8;
  if (jpeg) {
    // A JPEG cut short decodes to a partly grey picture with only a warning:
    // require the end-of-image marker (trailing padding allowed).
    size_t end = bytes.size();
    while (end > 2 && bytes[end - 1] == 0) --end;
    if (end < 4 || bytes[end - 2] != 0xFF || bytes[end - 1] != 0xD9) {
      ++next_frame_;
      return InvalidField("frame", "truncated JPEG (no end-of-image marker)");
    }
  }
  try {
    const cv::Mat buf(1, static_cast<int>(bytes.size()), CV_8UC1, const_cast<uint8_t*>(bytes.data()));
    // imdecode leaves `dst` as it was when decoding fails, so start empty (this
    // costs one allocation per encoded frame).
    decoded_.release();
    cv::imdecode(buf, cv::IMREAD_GRAYSCALE, &decoded_);
  } catch (const cv::Exception& e) {
    decoded_.release();
  }
  if (decoded_.empty()) {
    ++next_frame_;
    return InvalidField("frame", "cannot decode ", bytes.size(), " bytes as JPEG or PNG");
  }
  return Process(decoded_, time_s, out);
}

Status CubeTracker::ProcessRaw(std::span<const uint8_t> pixels, int width, int height, int channels, double time_s,
                               CubeState* out) {
  if (channels != 1 && channels != 3) {
    ++next_frame_;
    return InvalidField("frame.channels", channels, " (raw frames are 8-bit grey or BGR)");
  }
  if (width <= 0 || height <= 0 ||
      pixels.size() != static_cast<size_t>(width) * static_cast<size_t>(height) * static_cast<size_t>(channels)) {
    ++next_frame_;
    return InvalidField("frame", pixels.size(), " bytes do not make a ", width, "x", height, "x", channels,
                        " image");
  }
  const cv::Mat m(height, width, channels == 1 ? CV_8UC1 : CV_8UC3, const_cast<uint8_t*>(pixels.data()));
  return Process(m, time_s, out);
}

}  // namespace kinemo::cube
