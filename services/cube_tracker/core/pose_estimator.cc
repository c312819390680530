#include "services/cube_tracker/core/pose_estimator.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"

namespace kinemo::cube {
namespace {

double RotationAngle(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d d = a.t() * b;
  const double c = std::clamp((cv::trace(d) - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c);
}

}  // namespace

StatusOr<CubePoseEstimator> CubePoseEstimator::Create(const CubeModel& model, const CameraModel& camera,
                                                      const DetectorOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateCubeModel(model));
  KINEMO_RETURN_IF_ERROR(ValidateCameraModel(camera));
  if (options.full_search_every < 1) return InvalidField("detector.full_search_every", "must be >= 1");
  if (options.threshold_window_min < 3 || options.threshold_window_max < options.threshold_window_min ||
      options.threshold_window_step < 1) {
    return InvalidField("detector.threshold_window_*", "need 3 <= min <= max and step >= 1");
  }
  KINEMO_ASSIGN_OR_RETURN(int dict_id, DictionaryId(model.dictionary));
  CubePoseEstimator e;
  e.model_ = model;
  e.camera_ = camera;
  e.options_ = options;
  try {
    e.dictionary_ = cv::aruco::getPredefinedDictionary(dict_id);
    e.params_ = cv::aruco::DetectorParameters::create();
    e.params_->adaptiveThreshWinSizeMin = options.threshold_window_min;
    e.params_->adaptiveThreshWinSizeMax = options.threshold_window_max;
    e.params_->adaptiveThreshWinSizeStep = options.threshold_window_step;
    e.params_->cornerRefinementMethod =
        options.subpixel_corners ? cv::aruco::CORNER_REFINE_SUBPIX : cv::aruco::CORNER_REFINE_NONE;
    e.params_->cornerRefinementWinSize = 4;
    e.params_->cornerRefinementMinAccuracy = 0.01;
    e.params_->cornerRefinementMaxIterations = 50;
    e.coarse_params_ = cv::aruco::DetectorParameters::create();
    e.coarse_params_->adaptiveThreshWinSizeMin = 3;
    e.coarse_params_->adaptiveThreshWinSizeMax = std::max(3, options.threshold_window_max / 2);
    e.coarse_params_->adaptiveThreshWinSizeStep = std::max(1, options.threshold_window_step / 2);
    e.coarse_params_->cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;
  } catch (const cv::Exception& ex) {
    return absl::InternalError(absl::StrCat("aruco setup: ", ex.what()));
  }
  e.frames_since_full_ = options.full_search_every;
  e.K_ = cv::Mat(camera.K).clone();
  e.dist_ = camera.dist.clone();
  for (int f = 0; f < kNumFaces; ++f) {
    // Marker frame of IPPE_SQUARE: x right, y up, z out of the face.
    const FaceFrame& fr = FaceFrameOf(f);
    const cv::Vec3d y = -fr.down;
    Pose p;
    p.R = cv::Matx33d(fr.right[0], y[0], fr.normal[0], fr.right[1], y[1], fr.normal[1], fr.right[2], y[2],
                      fr.normal[2]);
    p.t = fr.normal * (model.cube_size_m / 2);
    e.cube_from_marker_[f] = p;
  }
  return e;
}

cv::Rect CubePoseEstimator::ProjectedBox(const Pose& cfc, double margin) const {
  const double h = model_.cube_size_m / 2;
  std::vector<cv::Point3d> pts;
  pts.reserve(8);
  for (int i = 0; i < 8; ++i) {
    cv::Vec3d p((i & 1) ? h : -h, (i & 2) ? h : -h, (i & 4) ? h : -h);
    cv::Vec3d c = cfc.Apply(p);
    if (c[2] <= 1e-3) return cv::Rect(0, 0, camera_.width, camera_.height);
    pts.emplace_back(c);
  }
  std::vector<cv::Point2d> img;
  cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K_, dist_, img);
  cv::Rect2d box = cv::boundingRect(std::vector<cv::Point2f>(img.begin(), img.end()));
  const double gx = box.width * margin, gy = box.height * margin, g = std::max(gx, gy);
  cv::Rect r(static_cast<int>(std::floor(box.x - g)), static_cast<int>(std::floor(box.y - g)),
             static_cast<int>(std::ceil(box.width + 2 * g)), static_cast<int>(std::ceil(box.height + 2 * g)));
  return r & cv::Rect(0, 0, camera_.width, camera_.height);
}

bool CubePoseEstimator::Detect(const cv::Mat& gray, const cv::Rect& window) {
  corners_.clear();
  ids_.clear();
  cv::aruco::detectMarkers(gray(window), dictionary_, corners_, ids_, params_, rejected_);
  if (window.x != 0 || window.y != 0) {
    const cv::Point2f off(static_cast<float>(window.x), static_cast<float>(window.y));
    for (auto& c : corners_) {
      for (auto& p : c) p += off;
    }
  }
  for (int id : ids_) {
    if (model_.FaceOfMarker(id) >= 0) return true;
  }
  return false;
}

bool CubePoseEstimator::Solve(const Pose* prior, const cv::Vec3d* up, PoseResult* out) {
  obj_.clear();
  img_.clear();
  obj_face_.clear();
  out->face_seen.fill(false);
  std::array<int, kNumFaces> marker_index;
  marker_index.fill(-1);
  for (size_t i = 0; i < ids_.size(); ++i) {
    const int f = model_.FaceOfMarker(ids_[i]);
    if (f < 0 || out->face_seen[f]) continue;  // not ours, or a duplicate id
    out->face_seen[f] = true;
    marker_index[f] = static_cast<int>(i);
    const auto mc = MarkerCorners(model_, f);
    for (int k = 0; k < 4; ++k) {
      obj_.push_back(mc[k]);
      img_.push_back(corners_[i][k]);
      obj_face_.push_back(f);
    }
  }
  out->markers = static_cast<int>(obj_.size() / 4);
  if (out->markers == 0) return false;

  // Candidates: two IPPE solutions per marker, plus the prior.
  std::array<Pose, 2 * kNumFaces + 1> cand;
  int n = 0;
  const float m = static_cast<float>(model_.marker_size_m / 2);
  const std::vector<cv::Point3f> square = {{-m, m, 0}, {m, m, 0}, {m, -m, 0}, {-m, -m, 0}};
  std::vector<cv::Mat> rvecs, tvecs;
  for (int f = 0; f < kNumFaces; ++f) {
    if (marker_index[f] < 0) continue;
    rvecs.clear();
    tvecs.clear();
    cv::solvePnPGeneric(square, corners_[marker_index[f]], K_, dist_, rvecs, tvecs, false,
                        cv::SOLVEPNP_IPPE_SQUARE);
    const Pose marker_from_cube = cube_from_marker_[f].Inverse();
    for (size_t s = 0; s < rvecs.size() && n < 2 * kNumFaces; ++s) {
      Pose cfm = Pose::FromRvecTvec(cv::Vec3d(rvecs[s].ptr<double>()), cv::Vec3d(tvecs[s].ptr<double>()));
      cand[n++] = cfm * marker_from_cube;
    }
  }
  if (prior != nullptr) cand[n++] = *prior;

  std::array<double, 2 * kNumFaces + 1> rms;
  double best = std::numeric_limits<double>::infinity();
  for (int c = 0; c < n; ++c) {
    rms[c] = std::numeric_limits<double>::infinity();
    const Pose& p = cand[c];
    bool facing = true;
    for (int f = 0; f < kNumFaces && facing; ++f) {
      if (!out->face_seen[f]) continue;
      const cv::Vec3d nrm = p.R * FaceFrameOf(f).normal;
      const cv::Vec3d ctr = p.Apply(FaceFrameOf(f).normal * (model_.cube_size_m / 2));
      if (nrm.dot(ctr) >= 0 || ctr[2] <= 0) facing = false;
    }
    if (!facing) continue;
    cv::projectPoints(obj_, p.Rvec(), p.t, K_, dist_, proj_);
    double sum = 0;
    for (size_t k = 0; k < proj_.size(); ++k) {
      const cv::Point2f d = proj_[k] - img_[k];
      sum += d.dot(d);
    }
    rms[c] = std::sqrt(sum / proj_.size());
    best = std::min(best, rms[c]);
  }
  if (!std::isfinite(best)) return false;
  const double plausible = best * options_.ambiguity_ratio + 0.5;
  int pick = -1;
  double pick_score = std::numeric_limits<double>::infinity();
  for (int c = 0; c < n; ++c) {
    if (!(rms[c] <= plausible)) continue;
    double score = rms[c];
    if (prior != nullptr) {
      score = RotationAngle(cand[c].R, prior->R);
    } else if (up != nullptr) {
      double tilt = CV_PI;
      for (int f = 0; f < kNumFaces; ++f) {
        const cv::Vec3d nrm = cand[c].R * FaceFrameOf(f).normal;
        tilt = std::min(tilt, std::acos(std::clamp(nrm.dot(*up), -1.0, 1.0)));
      }
      score = tilt;
    }
    if (score < pick_score) {
      pick_score = score;
      pick = c;
    }
  }
  cv::Vec3d rvec = cand[pick].Rvec(), tvec = cand[pick].t;
  if (obj_.size() >= 4) {
    cv::solvePnPRefineLM(obj_, img_, K_, dist_, rvec, tvec,
                         cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 20, 1e-9));
  }
  out->camera_from_cube = Pose::FromRvecTvec(rvec, tvec);
  cv::projectPoints(obj_, rvec, tvec, K_, dist_, proj_);
  double sum = 0;
  for (size_t k = 0; k < proj_.size(); ++k) {
    const cv::Point2f d = proj_[k] - img_[k];
    sum += d.dot(d);
  }
  out->rms_px = std::sqrt(sum / proj_.size());
  return out->rms_px <= options_.max_reprojection_px;
}

Status CubePoseEstimator::Estimate(const cv::Mat& gray, const Pose* prior, const cv::Vec3d* up,
                                   PoseResult* out) {
  out->found = false;
  out->markers = 0;
  out->rms_px = 0;
  out->face_seen.fill(false);
  if (gray.empty()) return InvalidField("frame", "empty image");
  if (gray.type() != CV_8UC1) return InvalidField("frame", "expected 8-bit grey, got type ", gray.type());
  if (gray.cols != camera_.width || gray.rows != camera_.height) {
    return InvalidField("frame", gray.cols, "x", gray.rows, " does not match the camera's ", camera_.width, "x",
                        camera_.height);
  }
  const cv::Rect full(0, 0, gray.cols, gray.rows);
  try {
    bool detected = false;
    if (options_.roi_tracking && prior != nullptr) {
      out->search_window = ProjectedBox(*prior, options_.roi_margin);
      if (out->search_window.area() > 0 && out->search_window != full) {
        detected = Detect(gray, out->search_window) && Solve(prior, up, out);
      }
    }
    bool full_search = !detected;
    // Coarse only while there is no prior: a cube just seen (and maybe half
    // hidden or blurred) gets the full-resolution search every frame.
    if (!detected && prior == nullptr && options_.coarse_search && gray.cols >= 160 && gray.rows >= 120) {
      full_search = false;
      cv::resize(gray, half_, cv::Size(gray.cols / 2, gray.rows / 2), 0, 0, cv::INTER_AREA);
      corners_.clear();
      ids_.clear();
      cv::aruco::detectMarkers(half_, dictionary_, corners_, ids_, coarse_params_, rejected_);
      float x0 = 1e9f, y0 = 1e9f, x1 = -1e9f, y1 = -1e9f;
      for (size_t i = 0; i < ids_.size(); ++i) {
        if (model_.FaceOfMarker(ids_[i]) < 0) continue;
        for (const cv::Point2f& p : corners_[i]) {
          x0 = std::min(x0, 2 * p.x);
          y0 = std::min(y0, 2 * p.y);
          x1 = std::max(x1, 2 * p.x);
          y1 = std::max(y1, 2 * p.y);
        }
      }
      if (x1 >= x0) {
        // The other faces of the cube can reach a marker's size beyond it.
        const float g = 2 * std::max(x1 - x0, y1 - y0) + 8;
        const cv::Rect window = cv::Rect(cv::Point(static_cast<int>(x0 - g), static_cast<int>(y0 - g)),
                                         cv::Point(static_cast<int>(x1 + g) + 1, static_cast<int>(y1 + g) + 1)) &
                                full;
        out->search_window = window;
        detected = window.area() > 0 && Detect(gray, window) && Solve(prior, up, out);
        full_search = !detected;
      } else if (frames_since_full_ >= options_.full_search_every) {
        full_search = true;
      }
      ++frames_since_full_;
    }
    if (full_search) {
      frames_since_full_ = 1;
      out->search_window = full;
      detected = Detect(gray, full) && Solve(prior, up, out);
    }
    // The first frame without a prior searches the full frame.
    if (prior != nullptr) frames_since_full_ = options_.full_search_every;
    out->found = detected;
  } catch (const cv::Exception& e) {
    return absl::InternalError(absl::StrCat("cube pose: OpenCV: ", e.what()));
  }
  return absl::OkStatus();
}

}  // namespace kinemo::cube
