// Gesture segments of a motion library (Gesture Controllers §5.1, §7.1).
//
// Every clip is cut where the mean speed of the two hands crosses a threshold
// and each segment gets the six kinematic parameters (T, D, V, A, C, H) on a
// log scale. Both are computed by common/gesture (gesture::ComputeKinematicSegments),
// which the inference corpus uses too, so that the hidden-state Gaussians of
// an inference model trained on that corpus describe these segments: same
// hand joints, same units (seconds, body heights), same logs, W_* = 1, mean
// magnitudes for V, A, C.
//
// Each segment a of n_a frames may be left at its last frame or at one of
// `interruption_frames` frames R_a placed at uniform intervals (3 in the
// paper); those are its "end points". Transition costs:
//   D_seg(a, b)  = w·pose(a_0, b_0) + |T_a − T_b| + |V_a − V_b| + |D_a − D_b|
//                  (segment length, initial pose, and the dynamics signature:
//                  log velocity and displacement)
//   D_s-p(a, b)  = D_seg(a₊, b) + D_seg(a, b₋), a₊ = a's successor and b₋ = b's
//                  predecessor in their clips (a missing neighbour's term is
//                  w·pose(last frame of a, b_0))
//   D_int(a,f,b,f') = w·pose(a_f, b_f') + interruption penalty
// where pose(x, y) is the RMS over joints of the difference of their
// positions relative to the root (in body heights) and velocities (body
// heights per 0.1 s), and w = transition_weight.
#pragma once

#include <array>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/status/status.h"
#include "services/planner/library/library.h"

namespace kinemo::planner::controller {

inline constexpr int kParams = 6;  // T, D, V, A, C, H
using ParamVector = Eigen::Matrix<double, kParams, 1>;

struct SegmentOptions {
  // Boundary where the mean hand speed crosses this, in body heights per
  // second. 0.15 = the inference corpus' value (use the same for a model
  // trained there).
  double speed_threshold_heights_per_s = 0.15;
  // Shorter segments merge into their predecessor (inference corpus: 0.1 s).
  double min_segment_s = 0.1;
  // Interruption frames per segment (paper: 3, uniformly spaced).
  int interruption_frames = 3;
  // Weight of the pose term in D_seg and D_int.
  double transition_weight = 20.0;
  // Added to D_int when a segment is left at an interruption frame.
  double interruption_penalty = 1.0;
};
Status ValidateSegmentOptions(const SegmentOptions& o);

struct GestureSegment {
  int clip = 0;          // index into Library::clips
  int first_frame = 0;   // in the clip
  int num_frames = 0;    // n_a
  ParamVector params;    // y_a
  int tone = 0;          // index into SegmentLibrary::tones
  int prev = -1, next = -1;           // neighbours in the clip, -1 = none
  std::vector<int> ends;              // end points: R_a ∪ {n_a − 1}, ascending, offsets in the segment
  int first_end = 0;                  // index of ends[0] in SegmentLibrary::end_points
  bool stroke = false;                // the fastest segment of a clip with keywords
  std::vector<int> keywords;          // indices into SegmentLibrary::keywords (strokes only)
};

struct EndPoint {
  int segment = 0;
  int k = 0;                 // index into the segment's ends
  int frame = 0;             // offset in the segment
  bool last = false;         // the segment's last frame (no continuation)
  int block_in = 0;          // frames of the block that ends here (see controller.h)
};

// The segments of a library with their transition costs. Immutable.
struct SegmentLibrary {
  std::shared_ptr<const Library> library;
  SegmentOptions options;
  std::vector<GestureSegment> segments;
  std::vector<EndPoint> end_points;
  std::vector<std::string> tones;     // sorted
  std::vector<std::string> keywords;  // sorted
  // Pose feature of every clip frame: rows = Σ clip frames (clip_row[c] is
  // clip c's first row), 6 values per joint.
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> pose;
  std::vector<int> clip_row;
  // Transition cost S(e, b) for entering segment b at its first frame from end
  // point e (D_s-p for a last frame, D_int for an interruption frame):
  // end_points × segments, row-major.
  std::vector<float> transition;
  // Library statistics for the "no pops" check: 99th percentile and maximum
  // of the per-frame largest joint angular speed inside clips, degrees/s.
  double angular_speed_p99_dps = 0;
  double angular_speed_max_dps = 0;
  // The pose motions begin and end with (FindRestFrame: hands low and still).
  RestFrame rest;
  // The level the library's soles stand at (LibraryGroundHeight), found once
  // here so that every stream's FrameAssembler reuses it: estimating it per
  // stream walked 2000 library poses, 9 % of the live stack's CPU at 128
  // streams. Not OK when the skeleton has no legs to plant.
  StatusOr<double> ground_height_m = absl::FailedPreconditionError("not estimated");

  int num_segments() const { return static_cast<int>(segments.size()); }
  int num_end_points() const { return static_cast<int>(end_points.size()); }
  float S(int e, int b) const { return transition[static_cast<size_t>(e) * segments.size() + b]; }
  // pose(x, y) between frame f of segment a and frame g of segment b.
  double PoseDistance(int a, int f, int b, int g) const;
  // D_int(e, b, g) (pose distance + interruption penalty if e is not last).
  double InterruptCost(int e, int b, int g) const;
  int ClipFrameRow(int segment, int f) const {
    const auto& s = segments[static_cast<size_t>(segment)];
    return clip_row[static_cast<size_t>(s.clip)] + s.first_frame + f;
  }
};

// Segments a library's clips (every clip must segment: errors name it).
StatusOr<std::shared_ptr<const SegmentLibrary>> BuildSegmentLibrary(std::shared_ptr<const Library> library,
                                                                    const SegmentOptions& options);

// Only the segment count of one clip (for LoadLibrary's ClipInfo).
StatusOr<int> CountSegments(const motion::Clip& clip, const SegmentOptions& options);

// Largest joint angular speed between frames f−1 and f of a frame matrix
// (rows = frames with the skeleton's channels), in degrees per second, over
// joints with rotation channels. f ≥ 1.
double MaxJointAngularSpeedDps(const motion::Skeleton& skeleton, std::span<const double> prev,
                               std::span<const double> cur, double frame_time_s);

}  // namespace kinemo::planner::controller
