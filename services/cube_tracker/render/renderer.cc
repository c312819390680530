#include "services/cube_tracker/render/renderer.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "common/json/json_fields.h"

namespace kinemo::cube {
namespace {

constexpr double kDeg = CV_PI / 180.0;

cv::Matx33d Rx(double deg) {
  const double c = std::cos(deg * kDeg), s = std::sin(deg * kDeg);
  return {1, 0, 0, 0, c, -s, 0, s, c};
}
cv::Matx33d Ry(double deg) {
  const double c = std::cos(deg * kDeg), s = std::sin(deg * kDeg);
  return {c, 0, s, 0, 1, 0, -s, 0, c};
}
cv::Matx33d Rz(double deg) {
  const double c = std::cos(deg * kDeg), s = std::sin(deg * kDeg);
  return {c, -s, 0, s, c, 0, 0, 0, 1};
}

// Rotation that puts `face` on top.
cv::Matx33d FaceUp(int face) {
  switch (face) {
    case 1:
      return Rx(180);
    case 2:
      return Ry(-90);
    case 3:
      return Ry(90);
    case 4:  // +Y up: Rx(90) takes +Y to +Z
      return Rx(90);
    case 5:
      return Rx(-90);
    default:
      return cv::Matx33d::eye();
  }
}

double Smooth(double s) { return s * s * (3 - 2 * s); }

double Wrap180(double deg) {
  double w = std::fmod(deg + 180.0, 360.0);
  if (w <= 0) w += 360.0;
  return w - 180.0;
}

// A key's values within the script bounds (renderer.h).
Status CheckKey(const RenderKey& k, size_t i) {
  auto field = [i](std::string_view name) { return kinemo::StrCat("keys[", i, "].", name); };
  if (!(k.t_s >= 0 && k.t_s <= kMaxRenderDurationS)) return InvalidField(field("t_s"), k.t_s, " is not in [0, 600] s");
  const std::pair<const char*, double> metres[] = {{"x_m", k.x_m}, {"y_m", k.y_m}, {"lift_m", k.lift_m}};
  for (const auto& [name, v] : metres) {
    if (!(std::abs(v) <= 10)) return InvalidField(field(name), v, " is not within 10 m");
  }
  const std::pair<const char*, double> degrees[] = {
      {"yaw_deg", k.yaw_deg}, {"roll_x_deg", k.roll_x_deg}, {"roll_y_deg", k.roll_y_deg}};
  for (const auto& [name, v] : degrees) {
    if (!(std::abs(v) <= 3600)) return InvalidField(field(name), v, " is not within ±3600°");
  }
  if (!(k.blur_px >= 0 && k.blur_px <= 100)) return InvalidField(field("blur_px"), k.blur_px, " is not in [0, 100]");
  if (!(k.light >= 0 && k.light <= 10)) return InvalidField(field("light"), k.light, " is not in [0, 10]");
  if (!(std::abs(k.hand) <= 10)) return InvalidField(field("hand"), k.hand, " is not in [-10, 10]");
  return absl::OkStatus();
}

}  // namespace

int64_t RenderScript::frame_count() const {
  return static_cast<int64_t>(std::floor(duration_s() * fps + 1e-9)) + 1;
}

StatusOr<RenderScript> ParseRenderScript(const std::string& text, const std::string& base_dir) {
  RenderScript s;
  // Numbers are read checked (finite; integers in range): nlohmann's
  // value(key, int) casts any float, undefined behaviour out of range.
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    if (!j.is_object()) return InvalidField("render script", "must be a JSON object");
    s.name = j.value("name", s.name);
    KINEMO_ASSIGN_OR_RETURN(s.fps, JsonNumber(j, "fps", s.fps, ""));
    KINEMO_ASSIGN_OR_RETURN(s.width, JsonInteger<int>(j, "width", s.width, "", kMinRenderSizePx, kMaxRenderSizePx));
    KINEMO_ASSIGN_OR_RETURN(s.height, JsonInteger<int>(j, "height", s.height, "", kMinRenderSizePx, kMaxRenderSizePx));
    KINEMO_ASSIGN_OR_RETURN(s.hfov_deg, JsonNumber(j, "hfov_deg", s.hfov_deg, ""));
    if (j.contains("camera")) {
      const auto& c = j["camera"];
      if (!c.is_object()) return InvalidField("camera", "must be an object");
      KINEMO_ASSIGN_OR_RETURN(s.camera_distance_m,
                              JsonNumber(c, "distance_m", s.camera_distance_m, "camera."));
      KINEMO_ASSIGN_OR_RETURN(s.camera_elevation_deg,
                              JsonNumber(c, "elevation_deg", s.camera_elevation_deg, "camera."));
      KINEMO_ASSIGN_OR_RETURN(s.camera_azimuth_deg,
                              JsonNumber(c, "azimuth_deg", s.camera_azimuth_deg, "camera."));
      if (c.contains("look_at_m")) {
        const auto& v = c["look_at_m"];
        if (!v.is_array() || v.size() != 3)
          return InvalidField("camera.look_at_m", "needs 3 values");
        for (int a = 0; a < 3; ++a) {
          if (!v[a].is_number() || !std::isfinite(v[a].get<double>())) {
            return InvalidField(absl::StrCat("camera.look_at_m[", a, "]"),
                                "must be a finite number");
          }
          s.look_at_m[a] = v[a].get<double>();
        }
      }
    }
    s.background = j.value("background", std::string());
    KINEMO_ASSIGN_OR_RETURN(s.initial_top_face,
                            JsonInteger<int>(j, "initial_top_face", 0, "", 0, kNumFaces - 1));
    KINEMO_ASSIGN_OR_RETURN(s.noise_sigma, JsonNumber(j, "noise_sigma", s.noise_sigma, ""));
    KINEMO_ASSIGN_OR_RETURN(
        s.motion_blur_samples,
        JsonInteger<int>(j, "motion_blur_samples", s.motion_blur_samples, "", 1, 32));
    KINEMO_ASSIGN_OR_RETURN(s.seed, JsonInteger<uint32_t>(j, "seed", s.seed, ""));
    if (!j.contains("keys") || !j["keys"].is_array() || j["keys"].empty()) {
      return InvalidField("keys", "a non-empty array of keyframes is required");
    }
    RenderKey prev;
    for (size_t i = 0; i < j["keys"].size(); ++i) {
      const auto& k = j["keys"][i];
      const std::string at = absl::StrCat("keys[", i, "].");
      if (!k.is_object()) return InvalidField(absl::StrCat("keys[", i, "]"), "must be an object");
      RenderKey r = prev;
      KINEMO_ASSIGN_OR_RETURN(r.t_s, JsonNumber(k, "t_s", prev.t_s, at));
      KINEMO_ASSIGN_OR_RETURN(r.x_m, JsonNumber(k, "x_m", prev.x_m, at));
      KINEMO_ASSIGN_OR_RETURN(r.y_m, JsonNumber(k, "y_m", prev.y_m, at));
      KINEMO_ASSIGN_OR_RETURN(r.lift_m, JsonNumber(k, "lift_m", prev.lift_m, at));
      KINEMO_ASSIGN_OR_RETURN(r.yaw_deg, JsonNumber(k, "yaw_deg", prev.yaw_deg, at));
      KINEMO_ASSIGN_OR_RETURN(r.roll_x_deg, JsonNumber(k, "roll_x_deg", prev.roll_x_deg, at));
      KINEMO_ASSIGN_OR_RETURN(r.roll_y_deg, JsonNumber(k, "roll_y_deg", prev.roll_y_deg, at));
      KINEMO_ASSIGN_OR_RETURN(r.hand, JsonNumber(k, "hand", prev.hand, at));
      KINEMO_ASSIGN_OR_RETURN(r.light, JsonNumber(k, "light", prev.light, at));
      KINEMO_ASSIGN_OR_RETURN(r.blur_px, JsonNumber(k, "blur_px", prev.blur_px, at));
      if (i > 0 && !(r.t_s > prev.t_s)) {
        return InvalidField(absl::StrCat(at, "t_s"), r.t_s, " must be after the previous key's ",
                            prev.t_s);
      }
      if (r.lift_m < 0) return InvalidField(absl::StrCat(at, "lift_m"), "must be >= 0");
      KINEMO_RETURN_IF_ERROR(CheckKey(r, i));
      s.keys.push_back(r);
      prev = r;
    }
  } catch (const nlohmann::json::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("render script: ", e.what()));
  }
  if (!(s.fps > 0 && s.fps <= 240)) return InvalidField("fps", s.fps, " is not in (0, 240]");
  if (s.frame_count() > kMaxRenderFrames) {
    return InvalidField(absl::StrCat("keys[", s.keys.size() - 1, "].t_s"), s.keys.back().t_s, " s at ", s.fps,
                        " fps makes ", s.frame_count(), " frames (at most ", kMaxRenderFrames, ")");
  }
  if (!(s.noise_sigma >= 0 && s.noise_sigma <= 100)) {
    return InvalidField("noise_sigma", s.noise_sigma, " is not in [0, 100]");
  }
  if (!(s.camera_distance_m > 0 && s.camera_distance_m <= 100)) {
    return InvalidField("camera.distance_m", s.camera_distance_m, " is not in (0, 100]");
  }
  if (!(s.hfov_deg > 10 && s.hfov_deg < 150)) return InvalidField("hfov_deg", s.hfov_deg, " is not in (10, 150)");
  if (s.background.empty()) return InvalidField("background", "a photograph is required");
  if (std::filesystem::path(s.background).is_relative() && !base_dir.empty()) {
    s.background = (std::filesystem::path(base_dir) / s.background).lexically_normal().string();
  }
  return s;
}

StatusOr<RenderScript> LoadRenderScript(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open render script"));
  std::stringstream ss;
  ss << in.rdbuf();
  auto s = ParseRenderScript(ss.str(), std::filesystem::path(path).parent_path().string());
  if (!s.ok()) return Annotate(s.status(), path);
  return s;
}

StatusOr<SequenceRenderer> SequenceRenderer::Create(const CubeModel& model, const RenderScript& script,
                                                    const TrackerOptions& conventions) {
  KINEMO_RETURN_IF_ERROR(ValidateCubeModel(model));
  if (script.keys.empty()) return InvalidField("keys", "empty");
  SequenceRenderer r;
  r.model_ = model;
  r.script_ = script;
  r.conv_ = conventions;
  r.rng_ = cv::RNG(script.seed);
  r.camera_ = PinholeCamera(script.width, script.height, script.hfov_deg);
  // The camera looks at look_at_m from a point on a sphere around it.
  const double el = script.camera_elevation_deg * kDeg, az = script.camera_azimuth_deg * kDeg;
  const cv::Vec3d C = script.look_at_m + script.camera_distance_m *
                                             cv::Vec3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                                       std::sin(el));
  cv::Vec3d z = script.look_at_m - C;
  z = z / cv::norm(z);
  cv::Vec3d x = z.cross(cv::Vec3d(0, 0, 1));
  if (cv::norm(x) < 1e-6) return InvalidField("camera.elevation_deg", "the camera may not look straight down");
  x = x / cv::norm(x);
  const cv::Vec3d y = z.cross(x);
  r.camera_from_world_.R = cv::Matx33d(x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2]);
  r.camera_from_world_.t = -(r.camera_from_world_.R * C);
  r.camera_.surface = r.camera_from_world_;
  try {
    cv::Mat bg = cv::imread(script.background, cv::IMREAD_COLOR);
    if (bg.empty()) return absl::NotFoundError(absl::StrCat("background: cannot read ", script.background));
    // Scale to cover the frame, then crop the centre.
    const double scale = std::max(static_cast<double>(script.width) / bg.cols,
                                  static_cast<double>(script.height) / bg.rows);
    cv::Mat scaled;
    cv::resize(bg, scaled, cv::Size(), scale, scale, scale < 1 ? cv::INTER_AREA : cv::INTER_CUBIC);
    const int ox = (scaled.cols - script.width) / 2, oy = (scaled.rows - script.height) / 2;
    r.background_ = scaled(cv::Rect(std::max(0, ox), std::max(0, oy), script.width, script.height)).clone();
    for (int f = 0; f < kNumFaces; ++f) {
      KINEMO_ASSIGN_OR_RETURN(cv::Mat tex, RenderFaceTexture(model, f, 384));
      r.textures_[f] = tex;
    }
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("renderer: OpenCV: ", e.what()));
  }
  return r;
}

Pose SequenceRenderer::CubeAt(double t, RenderKey* key) const {
  const auto& keys = script_.keys;
  RenderKey k = keys.back();
  if (t <= keys.front().t_s) {
    k = keys.front();
  } else {
    for (size_t i = 0; i + 1 < keys.size(); ++i) {
      if (t <= keys[i + 1].t_s) {
        const RenderKey& a = keys[i];
        const RenderKey& b = keys[i + 1];
        const double s = Smooth((t - a.t_s) / (b.t_s - a.t_s));
        auto mix = [s](double u, double v) { return u + (v - u) * s; };
        k.t_s = t;
        k.x_m = mix(a.x_m, b.x_m);
        k.y_m = mix(a.y_m, b.y_m);
        k.lift_m = mix(a.lift_m, b.lift_m);
        k.yaw_deg = mix(a.yaw_deg, b.yaw_deg);
        k.roll_x_deg = mix(a.roll_x_deg, b.roll_x_deg);
        k.roll_y_deg = mix(a.roll_y_deg, b.roll_y_deg);
        k.hand = s < 0.5 ? a.hand : b.hand;
        k.light = mix(a.light, b.light);
        k.blur_px = mix(a.blur_px, b.blur_px);
        break;
      }
    }
  }
  if (key != nullptr) *key = k;
  Pose p;
  p.R = Rz(k.yaw_deg) * Rx(k.roll_x_deg) * Ry(k.roll_y_deg) * FaceUp(script_.initial_top_face);
  const double h = model_.cube_size_m / 2;
  double lowest = 0;
  for (int i = 0; i < 8; ++i) {
    const cv::Vec3d c((i & 1) ? h : -h, (i & 2) ? h : -h, (i & 4) ? h : -h);
    lowest = std::min(lowest, (p.R * c)[2]);
  }
  p.t = cv::Vec3d(k.x_m, k.y_m, k.lift_m - lowest);
  return p;
}

void SequenceRenderer::Draw(const Pose& world_from_cube, const RenderKey& key, cv::Mat3f* acc,
                            cv::Mat1b* hand_mask) const {
  const Pose cfc = camera_from_world_ * world_from_cube;
  const cv::Vec3d light = cv::normalize(cv::Vec3d(0.3, -0.5, 1.0));
  const cv::Rect frame(0, 0, acc->cols, acc->rows);
  const int P = textures_[0].cols;
  const std::vector<cv::Point2f> src = {{-0.5f, -0.5f}, {P - 0.5f, -0.5f}, {P - 0.5f, P - 0.5f}, {-0.5f, P - 0.5f}};
  cv::Mat1b ones(P, P, uchar(255));
  for (int f = 0; f < kNumFaces; ++f) {
    const cv::Vec3d n_cam = cfc.R * FaceFrameOf(f).normal;
    const cv::Vec3d ctr = cfc.Apply(FaceFrameOf(f).normal * (model_.cube_size_m / 2));
    if (n_cam.dot(ctr) >= 0) continue;  // back face
    const auto corners = FaceCorners(model_, f);
    std::vector<cv::Point3d> pts;
    for (const auto& c : corners) pts.emplace_back(cfc.Apply(cv::Vec3d(c.x, c.y, c.z)));
    std::vector<cv::Point2d> dst_d;
    cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(camera_.K), camera_.dist, dst_d);
    const std::vector<cv::Point2f> dst(dst_d.begin(), dst_d.end());
    cv::Rect roi = cv::boundingRect(dst);
    roi.x -= 2;
    roi.y -= 2;
    roi.width += 4;
    roi.height += 4;
    roi &= frame;
    if (roi.area() <= 0) continue;
    std::vector<cv::Point2f> local = dst;
    for (auto& p : local) p -= cv::Point2f(static_cast<float>(roi.x), static_cast<float>(roi.y));
    const cv::Mat H = cv::getPerspectiveTransform(src, local);
    cv::Mat tex, alpha;
    cv::warpPerspective(textures_[f], tex, H, roi.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
    cv::warpPerspective(ones, alpha, H, roi.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
    const double shade = (0.45 + 0.55 * std::max(0.0, (world_from_cube.R * FaceFrameOf(f).normal).dot(light))) *
                         key.light;
    cv::Mat3f region = (*acc)(roi);
    for (int yy = 0; yy < roi.height; ++yy) {
      const uchar* t = tex.ptr<uchar>(yy);
      const uchar* a = alpha.ptr<uchar>(yy);
      cv::Vec3f* o = region.ptr<cv::Vec3f>(yy);
      for (int xx = 0; xx < roi.width; ++xx) {
        if (a[xx] == 0) continue;
        const float w = a[xx] / 255.f;
        const float v = static_cast<float>(t[xx] / 255.0 * shade * 255.0 / std::max(w, 1e-3f));
        const cv::Vec3f col(v * 0.93f + 6, v * 0.97f + 4, v);
        o[xx] = o[xx] * (1 - w) + col * w;
      }
    }
  }
  if (key.hand > 0.5) {
    // A thumb on the lower left of the front, a finger on the right side, an arm to the right edge.
    const double h = model_.cube_size_m / 2;
    // On the table the thumb pushes on the front face; lifted, the hand grips the left and right sides.
    const cv::Vec3d thumb_w =
        world_from_cube.t + (key.lift_m < 0.01 ? cv::Vec3d(-0.75 * h, -1.05 * h, -0.45 * h)
                                               : cv::Vec3d(-1.6 * h, 0.1 * h, -0.6 * h));
    const cv::Vec3d finger_w = world_from_cube.t + cv::Vec3d(1.6 * h, 0.1 * h, -0.6 * h);
    std::vector<cv::Point3d> pts = {camera_from_world_.Apply(thumb_w), camera_from_world_.Apply(finger_w)};
    std::vector<cv::Point2d> img_d;
    cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(camera_.K), camera_.dist, img_d);
    const std::vector<cv::Point2f> img(img_d.begin(), img_d.end());
    const double px_per_m = camera_.K(0, 0) / std::max(0.05, pts[0].z);
    const int r = static_cast<int>(0.5 * h * px_per_m);
    const cv::Scalar skin(110 * key.light, 150 * key.light, 205 * key.light);
    cv::Mat1b mask(acc->size(), uchar(0));
    cv::ellipse(mask, img[0], cv::Size(r, static_cast<int>(r * 1.5)), 30, 0, 360, cv::Scalar(255), cv::FILLED,
                cv::LINE_AA);
    cv::ellipse(mask, img[1], cv::Size(static_cast<int>(r * 0.7), static_cast<int>(r * 1.2)), -20, 0, 360,
                cv::Scalar(255), cv::FILLED, cv::LINE_AA);
    cv::line(mask, img[1], cv::Point2f(static_cast<float>(acc->cols + 50), img[1].y + 330), cv::Scalar(255),
             static_cast<int>(1.1 * h * px_per_m), cv::LINE_AA);
    for (int yy = 0; yy < acc->rows; ++yy) {
      const uchar* m = mask.ptr<uchar>(yy);
      cv::Vec3f* o = acc->ptr<cv::Vec3f>(yy);
      for (int xx = 0; xx < acc->cols; ++xx) {
        if (m[xx] == 0) continue;
        const float w = m[xx] / 255.f;
        const float shade = 0.85f + 0.15f * static_cast<float>(yy) / static_cast<float>(acc->rows);
        o[xx] = o[xx] * (1 - w) + cv::Vec3f(static_cast<float>(skin[0]), static_cast<float>(skin[1]),
                                            static_cast<float>(skin[2])) * (w * shade);
      }
    }
    if (hand_mask != nullptr) *hand_mask = mask;
  } else if (hand_mask != nullptr) {
    *hand_mask = cv::Mat1b(acc->size(), uchar(0));
  }
}

Status SequenceRenderer::Next(cv::Mat* bgr, TruthFrame* truth) {
  if (next_ >= frame_count()) return absl::OutOfRangeError("renderer: past the end of the script");
  const int64_t index = next_++;
  const double t = index / script_.fps;
  try {
    // Motion blur: average sub-frame renders over half a frame of exposure.
    const int S = script_.motion_blur_samples;
    const double exposure = 0.5 / script_.fps;
    cv::Mat3f sum(script_.height, script_.width, cv::Vec3f(0, 0, 0));
    cv::Mat1b hand_mask;
    RenderKey key;
    for (int s = 0; s < S; ++s) {
      const double ts = S == 1 ? t : t + exposure * (static_cast<double>(s) / (S - 1) - 0.5);
      RenderKey ks;
      const Pose wfc = CubeAt(ts, &ks);
      cv::Mat3f acc;
      background_.convertTo(acc, CV_32FC3, ks.light);
      Draw(wfc, ks, &acc, s == S / 2 ? &hand_mask : nullptr);
      if (s == S / 2) key = ks;
      sum += acc;
    }
    sum *= 1.0 / S;
    if (key.blur_px > 0.1) cv::GaussianBlur(sum, sum, cv::Size(0, 0), key.blur_px);
    if (script_.noise_sigma > 0) {
      cv::Mat3f noise(sum.size());
      rng_.fill(noise, cv::RNG::NORMAL, cv::Scalar::all(0), cv::Scalar::all(script_.noise_sigma));
      sum += noise;
    }
    sum.convertTo(*bgr, CV_8UC3);

    // Truth at the frame's time.
    RenderKey k;
    const Pose wfc = CubeAt(t, &k);
    TruthFrame& tf = *truth;
    tf = TruthFrame{};
    tf.frame = index;
    tf.time_s = t;
    tf.camera_from_cube = camera_from_world_ * wfc;
    tf.position_m = cv::Vec2d(wfc.t[0], wfc.t[1]);
    tf.height_m = k.lift_m;
    // Visible markers: facing the camera (< ~80 degrees), fully inside, not under the hand.
    const Pose& cfc = tf.camera_from_cube;
    for (int f = 0; f < kNumFaces; ++f) {
      const cv::Vec3d n_cam = cfc.R * FaceFrameOf(f).normal;
      const cv::Vec3d ctr = cfc.Apply(FaceFrameOf(f).normal * (model_.cube_size_m / 2));
      if (-n_cam.dot(ctr) / cv::norm(ctr) < 0.17) continue;
      const auto mc = MarkerCorners(model_, f);
      std::vector<cv::Point3d> pts;
      for (const auto& c : mc) pts.emplace_back(cfc.Apply(cv::Vec3d(c.x, c.y, c.z)));
      std::vector<cv::Point2d> img;
      cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(camera_.K), camera_.dist, img);
      bool inside = true;
      for (const auto& p : img) {
        inside &= p.x >= 2 && p.y >= 2 && p.x <= script_.width - 3 && p.y <= script_.height - 3;
      }
      if (!inside) continue;
      cv::Mat1b quad(hand_mask.size(), uchar(0));
      std::vector<cv::Point> poly;
      for (const auto& p : img) poly.emplace_back(cvRound(p.x), cvRound(p.y));
      cv::fillConvexPoly(quad, poly, cv::Scalar(255));
      // Hidden when more than 1 % of the marker is under the hand.
      const int area = cv::countNonZero(quad);
      cv::Mat1b covered = hand_mask > 127;
      cv::bitwise_and(quad, covered, covered);
      if (area > 0 && cv::countNonZero(covered) <= area / 100) ++tf.visible_markers;
    }
    tf.visible = tf.visible_markers > 0;

    const int face = TopFace(wfc.R);
    tf.top_face = face;
    tf.action = model_.ActionOfFace(face);
    tf.tilt_deg = std::acos(std::clamp((wfc.R * FaceFrameOf(face).normal)[2], -1.0, 1.0)) / kDeg;
    tf.resting = tf.height_m < 0.001 && tf.tilt_deg < 2.0;
    const double wrapped = FaceYawDeg(wfc.R, face);
    const bool flat = tf.tilt_deg < conv_.flat_tilt_deg && k.lift_m < conv_.rest_height_m;
    auto emit = [&](EventType type) {
      CubeEvent e;
      e.type = type;
      e.frame = index;
      e.time_s = t;
      e.top_face = top_face_;
      e.action = model_.ActionOfFace(top_face_);
      e.intensity = intensity_;
      tf.events.push_back(e);
    };
    if (tf.visible) {
      missed_ = 0;
      if (!visible_) {
        visible_ = true;
        emit(EventType::kFound);
      }
    } else if (visible_ && ++missed_ >= conv_.lost_after_frames) {
      visible_ = false;
      emit(EventType::kLost);
    }
    if (face != top_face_) {
      const int previous = top_face_;
      top_face_ = face;
      yaw_unwrapped_ = wrapped;
      yaw_anchor_ = wrapped;
      yaw_valid_ = flat;
      intensity_ = 0;
      last_event_intensity_ = 0;
      if (previous >= 0) {
        emit(EventType::kFaceChanged);
        tf.events.back().previous_face = previous;
      }
    } else {
      yaw_unwrapped_ += Wrap180(wrapped - yaw_unwrapped_);
      if (flat) {
        if (yaw_valid_) {
          intensity_ = std::clamp(intensity_ - (yaw_unwrapped_ - yaw_anchor_) / 360.0 * conv_.intensity_per_turn,
                                  -1.0, 1.0);
        }
        yaw_anchor_ = yaw_unwrapped_;
        yaw_valid_ = true;
      } else {
        yaw_valid_ = false;
      }
      const bool at_end = std::abs(intensity_) >= 1.0 && std::abs(last_event_intensity_) < 1.0;
      if (std::abs(intensity_ - last_event_intensity_) >= conv_.intensity_event_step - 1e-9 || at_end) {
        last_event_intensity_ = intensity_;
        emit(EventType::kIntensityChanged);
      }
    }
    if (tf.resting && top_face_ != last_launched_face_) {
      last_launched_face_ = top_face_;
      emit(EventType::kActionLaunched);
    }
    tf.yaw_deg = yaw_unwrapped_;
    tf.intensity = intensity_;
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("renderer: OpenCV: ", e.what()));
  }
  return absl::OkStatus();
}

std::string TruthToJson(const CameraModel& camera, const std::vector<TruthFrame>& frames) {
  nlohmann::json j;
  j["image_width"] = camera.width;
  j["image_height"] = camera.height;
  j["camera_matrix"] = {camera.K(0, 0), camera.K(0, 1), camera.K(0, 2), camera.K(1, 0), camera.K(1, 1),
                        camera.K(1, 2), camera.K(2, 0), camera.K(2, 1), camera.K(2, 2)};
  if (camera.surface) {
    const cv::Vec3d rv = camera.surface->Rvec();
    j["surface_rvec"] = {rv[0], rv[1], rv[2]};
    j["surface_tvec"] = {camera.surface->t[0], camera.surface->t[1], camera.surface->t[2]};
  }
  nlohmann::json arr = nlohmann::json::array();
  for (const TruthFrame& f : frames) {
    nlohmann::json o;
    o["frame"] = f.frame;
    o["time_s"] = f.time_s;
    o["visible"] = f.visible;
    o["visible_markers"] = f.visible_markers;
    o["top_face"] = f.top_face;
    o["action"] = std::string(ActionName(f.action));
    o["yaw_deg"] = f.yaw_deg;
    o["intensity"] = f.intensity;
    o["position_m"] = {f.position_m[0], f.position_m[1]};
    o["height_m"] = f.height_m;
    o["tilt_deg"] = f.tilt_deg;
    o["resting"] = f.resting;
    const cv::Vec3d rv = f.camera_from_cube.Rvec();
    o["camera_from_cube_rvec"] = {rv[0], rv[1], rv[2]};
    o["camera_from_cube_tvec"] = {f.camera_from_cube.t[0], f.camera_from_cube.t[1], f.camera_from_cube.t[2]};
    nlohmann::json ev = nlohmann::json::array();
    for (const CubeEvent& e : f.events) {
      nlohmann::json x;
      x["type"] = std::string(EventTypeName(e.type));
      x["top_face"] = e.top_face;
      x["action"] = std::string(ActionName(e.action));
      x["intensity"] = e.intensity;
      if (e.type == EventType::kFaceChanged) x["previous_face"] = e.previous_face;
      ev.push_back(x);
    }
    o["events"] = ev;
    arr.push_back(o);
  }
  j["frames"] = arr;
  return j.dump();
}

Status SequenceRenderer::RenderToFiles(const CubeModel& model, const RenderScript& script,
                                       const std::string& video_path, const std::string& truth_path,
                                       const std::string& camera_path, std::vector<TruthFrame>* truth_out) {
  KINEMO_ASSIGN_OR_RETURN(SequenceRenderer r, Create(model, script));
  std::vector<TruthFrame> truth;
  try {
    cv::VideoWriter writer(video_path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), script.fps,
                           cv::Size(script.width, script.height), true);
    if (!writer.isOpened()) {
      return absl::FailedPreconditionError(absl::StrCat(video_path, ": cannot open an MJPG AVI writer"));
    }
    writer.set(cv::VIDEOWRITER_PROP_QUALITY, 95);
    cv::Mat frame;
    for (int64_t i = 0; i < r.frame_count(); ++i) {
      TruthFrame tf;
      KINEMO_RETURN_IF_ERROR(r.Next(&frame, &tf));
      writer.write(frame);
      truth.push_back(std::move(tf));
    }
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat(video_path, ": OpenCV: ", e.what()));
  }
  if (!truth_path.empty()) {
    std::ofstream out(truth_path);
    if (!out) return absl::PermissionDeniedError(absl::StrCat(truth_path, ": cannot write"));
    out << TruthToJson(r.camera(), truth) << "\n";
    if (!out) return absl::DataLossError(absl::StrCat(truth_path, ": write failed"));
  }
  if (!camera_path.empty()) KINEMO_RETURN_IF_ERROR(SaveCameraModel(r.camera(), camera_path));
  if (truth_out != nullptr) *truth_out = std::move(truth);
  return absl::OkStatus();
}

}  // namespace kinemo::cube
