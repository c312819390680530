#include "services/cube_tracker/ar/ar_view.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "common/motion/kinematics.h"
#include "common/retarget/retarget.h"

namespace kinemo::cube::ar {
namespace {

// The rig's (x, y up, z forward) -> the table's (x, y, z up).
Eigen::Matrix3d RigToTable() {
  Eigen::Matrix3d a;
  a << 1, 0, 0,  //
      0, 0, -1,  //
      0, 1, 0;
  return a;
}

// surface = offset + linear · x
struct Affine {
  Eigen::Matrix3d linear;
  Eigen::Vector3d offset;
};

Affine PlacementTransform(const Placement& p) {
  const Eigen::Matrix3d turn = Eigen::AngleAxisd(p.yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                               RigToTable() *
                               Eigen::AngleAxisd(-p.facing_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Affine a;
  a.linear = p.scale * turn;
  const Eigen::Vector3d origin(p.origin.x(), 0, p.origin.z());
  a.offset = Eigen::Vector3d(p.position_m[0], p.position_m[1], 0) - a.linear * origin;
  return a;
}

// sRGB encoding of a linear value in [0, 1].
double ToSrgb(double v) {
  v = std::clamp(v, 0.0, 1.0);
  return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
}

// The way the body faces in the rig's world: perpendicular to the shoulder
// and hip lines (right -> left joints, the two averaged) and to +y, not unit;
// zero without those joints.
Eigen::Vector3d BodyForward(const retarget::Rig& rig, const std::vector<Eigen::Vector3d>& pos) {
  using retarget::roles::Side;
  Eigen::Vector3d left = Eigen::Vector3d::Zero();
  for (int bone : {retarget::roles::kUpperArm, retarget::roles::kThigh}) {
    const int l = rig.roles.joint[Side(0, bone)], r = rig.roles.joint[Side(1, bone)];
    if (l >= 0 && r >= 0) left += (pos[static_cast<size_t>(l)] - pos[static_cast<size_t>(r)]).normalized();
  }
  return left.cross(Eigen::Vector3d::UnitY());
}

// The clip's facing, as the angle from +z about +y: the body's forward
// (BodyForward) averaged over the clip, so that the character faces the
// camera on the whole, whatever its first frame does; and the hips' position
// at frame 0.
void ClipFrame(const retarget::Rig& rig, const motion::Clip& clip, Eigen::Vector3d* origin, double* facing) {
  *origin = Eigen::Vector3d::Zero();
  *facing = 0;
  const int hips = rig.roles.joint[retarget::roles::kHips];
  if (clip.num_frames() == 0 || hips < 0) return;
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(clip.skeleton.num_joints()));
  std::vector<Eigen::Matrix3d> rot(pos.size());
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int f = 0; f < clip.num_frames(); ++f) {
    if (!motion::ComputeWorldPose(clip.skeleton, clip.frame(f), pos, rot).ok()) return;
    if (f == 0) *origin = pos[static_cast<size_t>(hips)];
    const Eigen::Vector3d fwd = BodyForward(rig, pos);
    const double n = std::hypot(fwd.x(), fwd.z());
    if (n > 1e-12) sum += fwd / n;
  }
  if (std::hypot(sum.x(), sum.z()) > 1e-9) *facing = std::atan2(sum.x(), sum.z());
}

}  // namespace

Status ValidateArOptions(const ArOptions& o) {
  if (!(o.character_height_m > 0.001 && o.character_height_m <= 10)) {
    return InvalidField("character_height_m", "must be in (0.001, 10] m, got ", o.character_height_m);
  }
  if (!(std::abs(o.beside_m) <= 10)) return InvalidField("beside_m", "must be within ±10 m, got ", o.beside_m);
  if (!(o.shadow_opacity >= 0 && o.shadow_opacity <= 1)) {
    return InvalidField("shadow_opacity", "must be in [0, 1], got ", o.shadow_opacity);
  }
  return absl::OkStatus();
}

Placement PlaceBeside(const cv::Vec2d& cube_position_m, const Pose& camera_from_surface, double rig_height,
                      const ArOptions& options) {
  const Pose surface_from_camera = camera_from_surface.Inverse();
  // The camera's right (its x axis) on the table.
  const cv::Vec3d right = surface_from_camera.R * cv::Vec3d(1, 0, 0);
  cv::Vec2d side(right[0], right[1]);
  const double n = cv::norm(side);
  side = n > 1e-9 ? side / n : cv::Vec2d(1, 0);
  Placement p;
  p.position_m = cube_position_m + options.beside_m * side;
  // Facing the camera's foot point on the table: the turned forward (−y of
  // the table before the turn) is (sin yaw, −cos yaw).
  const cv::Vec3d eye = surface_from_camera.t;
  const cv::Vec2d to_eye(eye[0] - p.position_m[0], eye[1] - p.position_m[1]);
  p.yaw_rad = cv::norm(to_eye) > 1e-9 ? std::atan2(to_eye[0], -to_eye[1]) : 0;
  p.scale = rig_height > 0 ? options.character_height_m / rig_height : 1;
  return p;
}

cv::Vec3d ToSurface(const Placement& placement, const Eigen::Vector3d& rig_point) {
  const Affine a = PlacementTransform(placement);
  const Eigen::Vector3d s = a.linear * rig_point + a.offset;
  return {s.x(), s.y(), s.z()};
}

StatusOr<std::unique_ptr<CharacterView>> CharacterView::Create(std::shared_ptr<const retarget::Rig> rig,
                                                               double shadow_opacity) {
  if (!rig) return absl::InvalidArgumentError("rig: none");
  std::unique_ptr<CharacterView> v(new CharacterView());
  v->shadow_opacity_ = shadow_opacity;
  KINEMO_ASSIGN_OR_RETURN(v->mesh_, retarget::LoadCharacterMesh(*rig));
  for (int side = 0; side < 2; ++side) {
    int j = rig->roles.joint[retarget::roles::Side(side, retarget::roles::kToes)];
    if (j < 0) j = rig->roles.joint[retarget::roles::Side(side, retarget::roles::kFoot)];
    if (j < 0) return InvalidField("rig", "has no feet to stand on");
    v->sole_joint_[static_cast<size_t>(side)] = j;
    v->sole_offset_[static_cast<size_t>(side)] = rig->skeleton.joint(j).end_site.value_or(Eigen::Vector3d::Zero());
  }
  v->rig_ = std::move(rig);
  return v;
}

Status CharacterView::Draw(std::span<const double> frame, const Placement& placement, const CameraModel& camera,
                           const Pose& camera_from_surface, cv::Mat* bgr, DrawInfo* info) {
  *info = DrawInfo();
  if (bgr->type() != CV_8UC3 || bgr->cols != camera.width || bgr->rows != camera.height) {
    return InvalidField("frame", "must be 8-bit BGR of the camera's size ", camera.width, "x", camera.height);
  }
  KINEMO_RETURN_IF_ERROR(retarget::ComputeSkinPose(*rig_, frame, &pose_));
  retarget::SkinMesh(mesh_, pose_, &skinned_, &normals_);
  const Affine place = PlacementTransform(placement);
  const Eigen::Matrix3d turn = place.linear / placement.scale;
  const size_t n = skinned_.size();
  surface_.resize(n);
  depth_.resize(n);
  for (size_t v = 0; v < n; ++v) {
    const Eigen::Vector3d s = place.linear * skinned_[v].cast<double>() + place.offset;
    surface_[v] = cv::Point3d(s.x(), s.y(), s.z());
    const cv::Vec3d c = camera_from_surface.Apply(cv::Vec3d(s.x(), s.y(), s.z()));
    depth_[v] = c[2];
  }
  const cv::Vec3d rvec = camera_from_surface.Rvec();
  const cv::Vec3d tvec = camera_from_surface.t;
  cv::projectPoints(surface_, rvec, tvec, cv::Mat(camera.K), camera.dist, image_);

  // The soles, for callers that check where the feet stand.
  {
    std::vector<Eigen::Vector3d> pos(static_cast<size_t>(rig_->skeleton.num_joints()));
    std::vector<Eigen::Matrix3d> rot(pos.size());
    KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(rig_->skeleton, frame, pos, rot));
    std::vector<cv::Point3d> soles;
    for (size_t side = 0; side < 2; ++side) {
      const size_t j = static_cast<size_t>(sole_joint_[side]);
      const Eigen::Vector3d rig_point = pos[j] + rot[j] * sole_offset_[side];
      info->soles_rig[side] = rig_point;
      const Eigen::Vector3d s = place.linear * rig_point + place.offset;
      info->soles_surface_m[side] = cv::Vec3d(s.x(), s.y(), s.z());
      soles.emplace_back(s.x(), s.y(), s.z());
    }
    std::vector<cv::Point2d> px;
    cv::projectPoints(soles, rvec, tvec, cv::Mat(camera.K), camera.dist, px);
    info->soles_px = {px[0], px[1]};
    const Eigen::Vector3d forward = place.linear * BodyForward(*rig_, pos);
    const double n = std::hypot(forward.x(), forward.y());
    if (n > 1e-12) info->facing_surface = cv::Vec2d(forward.x() / n, forward.y() / n);
  }

  // Contact shadow: an ellipse on the table under the feet.
  if (placement.scale > 0 && shadow_opacity_ > 0) {
    const cv::Vec3d mid = 0.5 * (info->soles_surface_m[0] + info->soles_surface_m[1]);
    const double radius = 0.22 * height() * placement.scale;
    std::vector<cv::Point3d> ring;
    for (int k = 0; k < 32; ++k) {
      const double a = 2 * M_PI * k / 32;
      ring.emplace_back(mid[0] + radius * std::cos(a), mid[1] + 0.6 * radius * std::sin(a), 0);
    }
    std::vector<cv::Point2d> ring_px;
    cv::projectPoints(ring, rvec, tvec, cv::Mat(camera.K), camera.dist, ring_px);
    std::vector<cv::Point> poly;
    for (const auto& q : ring_px) poly.emplace_back(cvRound(q.x), cvRound(q.y));
    cv::Mat1b mask = cv::Mat1b::zeros(bgr->size());
    cv::fillPoly(mask, std::vector<std::vector<cv::Point>>{poly}, 255, cv::LINE_AA);
    cv::GaussianBlur(mask, mask, cv::Size(0, 0), std::max(1.0, radius * camera.K(0, 0) / 8 / std::max(0.05, tvec[2])));
    const double opacity = shadow_opacity_;
    for (int y = 0; y < bgr->rows; ++y) {
      auto* row = bgr->ptr<cv::Vec3b>(y);
      const auto* m = mask.ptr<uchar>(y);
      for (int x = 0; x < bgr->cols; ++x) {
        if (m[x] == 0) continue;
        const double k = 1 - opacity * m[x] / 255.0;
        for (int c = 0; c < 3; ++c) row[x][c] = cv::saturate_cast<uchar>(row[x][c] * k);
      }
    }
  }

  // Triangles: front faces, z-buffered, flat Lambert shading (light from
  // above, in front and to the left of the character, in the table frame).
  zbuffer_.create(bgr->size());
  zbuffer_.setTo(std::numeric_limits<float>::infinity());
  const Eigen::Vector3d light = Eigen::Vector3d(-0.4, -0.6, 1.0).normalized();
  const double near_m = 0.01;
  const int w = bgr->cols, h = bgr->rows;
  for (size_t t = 0; t < mesh_.triangles.size(); ++t) {
    const auto& tri = mesh_.triangles[t];
    const size_t i0 = static_cast<size_t>(tri[0]), i1 = static_cast<size_t>(tri[1]), i2 = static_cast<size_t>(tri[2]);
    if (depth_[i0] < near_m || depth_[i1] < near_m || depth_[i2] < near_m) continue;
    const cv::Point2d a = image_[i0], b = image_[i1], c = image_[i2];
    // Signed screen area: negative for a face turned to the camera (its
    // counter-clockwise order seen from outside, in image axes with y down).
    const double area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    if (!(area < -1e-12)) continue;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({a.x, b.x, c.x}))));
    const int x1 = std::min(w - 1, static_cast<int>(std::ceil(std::max({a.x, b.x, c.x}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({a.y, b.y, c.y}))));
    const int y1 = std::min(h - 1, static_cast<int>(std::ceil(std::max({a.y, b.y, c.y}))));
    if (x0 > x1 || y0 > y1) continue;
    // Shading from the face's averaged vertex normal, in the table frame.
    const Eigen::Vector3d nrm =
        (turn * (normals_[i0] + normals_[i1] + normals_[i2]).cast<double>()).normalized();
    const double shade = 0.42 + 0.58 * std::max(0.0, nrm.dot(light));
    const Eigen::Vector4f& base = mesh_.base_colors[static_cast<size_t>(mesh_.triangle_material[t])];
    const cv::Vec3b color(cv::saturate_cast<uchar>(255 * ToSrgb(base[2] * shade)),
                          cv::saturate_cast<uchar>(255 * ToSrgb(base[1] * shade)),
                          cv::saturate_cast<uchar>(255 * ToSrgb(base[0] * shade)));
    const double za = depth_[i0], zb = depth_[i1], zc = depth_[i2];
    for (int y = y0; y <= y1; ++y) {
      const double py = y + 0.5;
      auto* row = bgr->ptr<cv::Vec3b>(y);
      float* zrow = zbuffer_.ptr<float>(y);
      for (int x = x0; x <= x1; ++x) {
        const double px = x + 0.5;
        const double wa = ((b.x - px) * (c.y - py) - (b.y - py) * (c.x - px)) / area;
        const double wb = ((c.x - px) * (a.y - py) - (c.y - py) * (a.x - px)) / area;
        const double wc = 1 - wa - wb;
        if (wa < 0 || wb < 0 || wc < 0) continue;
        // Perspective-correct depth: 1/z is linear on the screen.
        const float z = static_cast<float>(1.0 / (wa / za + wb / zb + wc / zc));
        if (z >= zrow[x]) continue;
        if (std::isinf(zrow[x])) ++info->pixels;
        zrow[x] = z;
        row[x] = color;
      }
    }
  }
  info->drawn = info->pixels > 0;
  return absl::OkStatus();
}

StatusOr<ActionPlayer> ActionPlayer::Create(const retarget::Rig& rig, std::vector<Source> sources) {
  ActionPlayer p;
  for (size_t i = 0; i < sources.size(); ++i) {
    Source& s = sources[i];
    const std::string field = kinemo::StrCat("clips[", i, "]");
    if (s.clip.num_frames() == 0) return InvalidField(field, "has no frames");
    retarget::RetargetOptions options;
    auto source_rig = retarget::RigFromSkeleton(s.clip.skeleton, 1.0, field);
    if (!source_rig.ok()) return Annotate(source_rig.status(), field);
    const double mpu = s.meters_per_unit > 0 ? s.meters_per_unit : retarget::EstimateMetersPerUnit(*source_rig);
    auto out = retarget::RetargetClip(s.clip, mpu, rig, options);
    if (!out.ok()) return Annotate(out.status(), field);
    Played played;
    played.action = s.action;
    played.clip = std::move(out->clip);
    ClipFrame(rig, played.clip, &played.origin, &played.facing_rad);
    p.clips_.push_back(std::move(played));
  }
  if (p.clips_.empty()) return InvalidField("clips", "give at least one action's clip");
  return p;
}

std::span<const double> ActionPlayer::At(Action action, double time_s, Placement* placement) {
  int want = -1;
  for (size_t i = 0; i < clips_.size(); ++i) {
    if (clips_[i].action == action) want = static_cast<int>(i);
  }
  if (want < 0) want = current_ >= 0 ? current_ : 0;
  if (want != current_) {
    current_ = want;
    started_s_ = time_s;
  }
  const Played& p = clips_[static_cast<size_t>(current_)];
  playing_ = p.action;
  const int n = p.clip.num_frames();
  const double t = std::max(0.0, time_s - started_s_);
  const int f = static_cast<int>(std::llround(t / p.clip.frame_time_s)) % n;
  placement->origin = p.origin;
  placement->facing_rad = p.facing_rad;
  return p.clip.frame(f);
}

Status ArOverlay::Compose(const CubeState& state, const std::optional<Pose>& surface, const CameraModel& camera,
                          double time_s, cv::Mat* bgr, DrawInfo* info) {
  *info = DrawInfo();
  if (state.visible) {
    cube_position_m_ = state.position_m;
    placed_ = true;
  }
  const Action action = state.action == Action::kUnknown ? Action::kIdle : state.action;
  Placement clip_frame;
  const std::span<const double> frame = player_.At(action, time_s, &clip_frame);
  if (!placed_ || !surface) return absl::OkStatus();
  placement_ = PlaceBeside(cube_position_m_, *surface, view_->height(), options_);
  placement_.origin = clip_frame.origin;
  placement_.facing_rad = clip_frame.facing_rad;
  return view_->Draw(frame, placement_, camera, *surface, bgr, info);
}

}  // namespace kinemo::cube::ar
