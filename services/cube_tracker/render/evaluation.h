// Compares tracker output with rendered ground truth.
#pragma once

#include <string>
#include <vector>

#include "services/cube_tracker/core/tracker.h"
#include "services/cube_tracker/render/renderer.h"

namespace kinemo::cube {

struct TrackingReport {
  int frames = 0;
  int truth_visible = 0;          // frames where the truth says a marker is in view
  int tracked_visible = 0;        // of those, frames the tracker reported visible
  int top_face_right = 0;         // of those, frames with the right top face
  int false_visible = 0;          // tracker visible while the truth says not
  double detection_rate = 0;      // tracked_visible / truth_visible
  double top_face_accuracy = 0;   // top_face_right / tracked_visible
  double yaw_err_median_deg = 0;  // on tracked frames, flat cube, same top face
  double yaw_err_p95_deg = 0;
  double pos_err_median_m = 0;    // on tracked frames with the cube resting
  double pos_err_p95_m = 0;
  double pos_err_max_m = 0;
  double intensity_err_max = 0;   // on tracked frames
  double intensity_err_p99 = 0;
  // Gesture events (face_changed, action_launched): matched within the tolerance.
  int truth_events = 0;
  int matched_events = 0;
  int missed_events = 0;
  int spurious_events = 0;
  int max_event_offset_frames = 0;
  // Visibility events (lost, found), reported apart: partial occlusion by the hand
  // makes them depend on how much of a marker ArUco still decodes.
  int truth_visibility_events = 0;
  int matched_visibility_events = 0;
  int spurious_visibility_events = 0;
  std::vector<std::string> event_notes;  // one line per missed or spurious event

  std::string Summary() const;
};

// `states[i]` and `truth[i]` describe the same frame.
TrackingReport EvaluateTracking(const std::vector<TruthFrame>& truth, const std::vector<CubeState>& states,
                                int event_tolerance_frames = 3);

}  // namespace kinemo::cube
