#include "services/cube_tracker/render/evaluation.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace kinemo::cube {
namespace {

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t i = std::min(v.size() - 1, static_cast<size_t>(std::floor(q * (v.size() - 1) + 0.5)));
  return v[i];
}

double WrapDiff(double a, double b) {
  double d = std::fmod(a - b + 180.0, 360.0);
  if (d < 0) d += 360.0;
  return d - 180.0;
}

bool Gesture(EventType t) { return t == EventType::kFaceChanged || t == EventType::kActionLaunched; }
bool Visibility(EventType t) { return t == EventType::kLost || t == EventType::kFound; }

}  // namespace

std::string TrackingReport::Summary() const {
  return absl::StrFormat(
      "frames %d, truth visible %d, detection %.4f, top face %.4f, false visible %d, "
      "yaw err median %.3f deg p95 %.3f, position err median %.2f mm p95 %.2f max %.2f, "
      "intensity err max %.4f p99 %.4f, gesture events %d/%d matched, %d missed, %d spurious, max offset %d "
      "frames; lost/found %d/%d matched, %d spurious",
      frames, truth_visible, detection_rate, top_face_accuracy, false_visible, yaw_err_median_deg, yaw_err_p95_deg,
      pos_err_median_m * 1000, pos_err_p95_m * 1000, pos_err_max_m * 1000, intensity_err_max, intensity_err_p99,
      matched_events, truth_events, missed_events, spurious_events, max_event_offset_frames,
      matched_visibility_events, truth_visibility_events, spurious_visibility_events);
}

TrackingReport EvaluateTracking(const std::vector<TruthFrame>& truth, const std::vector<CubeState>& states,
                                int tol) {
  TrackingReport r;
  const size_t n = std::min(truth.size(), states.size());
  r.frames = static_cast<int>(n);
  std::vector<double> yaw_err, pos_err, int_err;
  for (size_t i = 0; i < n; ++i) {
    const TruthFrame& t = truth[i];
    const CubeState& s = states[i];
    if (!t.visible) {
      if (s.visible) ++r.false_visible;
      continue;
    }
    ++r.truth_visible;
    if (!s.visible) continue;
    ++r.tracked_visible;
    int_err.push_back(std::abs(s.intensity - t.intensity));
    if (s.top_face == t.top_face) {
      ++r.top_face_right;
      if (t.tilt_deg < 20) yaw_err.push_back(std::abs(WrapDiff(s.yaw_deg, t.yaw_deg)));
    }
    if (t.resting) pos_err.push_back(cv::norm(s.position_m - t.position_m));
  }
  r.detection_rate = r.truth_visible ? static_cast<double>(r.tracked_visible) / r.truth_visible : 0;
  r.top_face_accuracy = r.tracked_visible ? static_cast<double>(r.top_face_right) / r.tracked_visible : 0;
  r.yaw_err_median_deg = Quantile(yaw_err, 0.5);
  r.yaw_err_p95_deg = Quantile(yaw_err, 0.95);
  r.pos_err_median_m = Quantile(pos_err, 0.5);
  r.pos_err_p95_m = Quantile(pos_err, 0.95);
  r.pos_err_max_m = pos_err.empty() ? 0 : *std::max_element(pos_err.begin(), pos_err.end());
  r.intensity_err_max = int_err.empty() ? 0 : *std::max_element(int_err.begin(), int_err.end());
  r.intensity_err_p99 = Quantile(int_err, 0.99);

  struct Ev {
    int64_t frame;
    EventType type;
    int face;
    bool used;
  };
  std::vector<Ev> te, se;
  for (size_t i = 0; i < n; ++i) {
    for (const auto& e : truth[i].events) {
      if (Gesture(e.type) || Visibility(e.type)) te.push_back({static_cast<int64_t>(i), e.type, e.top_face, false});
    }
    for (const auto& e : states[i].events) {
      if (Gesture(e.type) || Visibility(e.type)) se.push_back({static_cast<int64_t>(i), e.type, e.top_face, false});
    }
  }
  for (Ev& t : te) {
    const bool gesture = Gesture(t.type);
    (gesture ? r.truth_events : r.truth_visibility_events)++;
    Ev* best = nullptr;
    for (Ev& s : se) {
      if (s.used || s.type != t.type) continue;
      if (t.type == EventType::kFaceChanged || t.type == EventType::kActionLaunched) {
        if (s.face != t.face) continue;
      }
      if (std::abs(s.frame - t.frame) > tol) continue;
      if (best == nullptr || std::abs(s.frame - t.frame) < std::abs(best->frame - t.frame)) best = &s;
    }
    if (best != nullptr) {
      best->used = true;
      t.used = true;
      if (!gesture) {
        ++r.matched_visibility_events;
        continue;
      }
      ++r.matched_events;
      r.max_event_offset_frames =
          std::max(r.max_event_offset_frames, static_cast<int>(std::abs(best->frame - t.frame)));
    } else {
      if (gesture) ++r.missed_events;
      r.event_notes.push_back(absl::StrCat("missed ", EventTypeName(t.type), " face ", t.face, " at frame ", t.frame));
    }
  }
  for (const Ev& s : se) {
    if (!s.used) {
      (Gesture(s.type) ? r.spurious_events : r.spurious_visibility_events)++;
      r.event_notes.push_back(
          absl::StrCat("spurious ", EventTypeName(s.type), " face ", s.face, " at frame ", s.frame));
    }
  }
  return r;
}

}  // namespace kinemo::cube
