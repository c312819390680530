// Gesture kinematics shared by the inference corpus (the training side) and
// the planner's Gesture Controller (the synthesis side): one home, so that
// the hidden-state Gaussians of a model trained on a corpus describe the
// segments the controller plays — same hand joints, same units, same logs.
//
// Gesture Controllers (Levine et al. 2010):
//   §5.1  motion is cut into gesture segments where the hands' speed crosses a
//         threshold; each segment gets kinematic parameters y = (T, D, V, A,
//         C, H): duration, displacement, velocity, acceleration, curvature
//         and hand height, on log scales with unit scales B_* and weights W_*.
//   §7.1  the controller's library is segmented the same way.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::gesture {

// The two hands (wrists) of a clip over time, in body heights (head above the
// lower foot in frame 0; Y up), and their summed height above the floor.
struct HandTrack {
  Eigen::MatrixXd p;  // frames × 6: left xyz, right xyz, body heights
  Eigen::VectorXd h;  // sum of hand heights above the floor, body heights
  double dt = 1.0 / 30.0;
  double body_height = 0;  // in the clip's units
};
StatusOr<HandTrack> ComputeHandTrack(const motion::Clip& clip);

// Central differences (one-sided at the ends), rows = frames.
Eigen::MatrixXd TimeDerivative(const Eigen::MatrixXd& x, double dt);

// Mean speed of the two hands per frame from a frames × 6 velocity matrix.
Eigen::VectorXd MeanHandSpeed(const Eigen::MatrixXd& velocity);

// Kinematic parameters of one motion segment (§5.1).
struct KinematicSegment {
  double start_s = 0.0;
  double end_s = 0.0;
  Eigen::Matrix<double, 6, 1> params;  // T, D, V, A, C, H
};

struct KinematicOptions {
  // Segment boundaries where the mean speed of the two hands crosses this,
  // in body heights per second (0.15 ≈ 0.25 m/s for a 1.7 m body).
  double speed_threshold_heights_per_s = 0.15;
  // Shorter segments are merged into their predecessor.
  double min_segment_s = 0.1;
};

// Segments a clip at hand-speed threshold crossings and computes, per segment
// of frames 1..n (dt = frame time, positions in body heights, p/v/a the two
// hands' 6-D position/velocity/acceleration, h the sum of hand heights above
// the floor):
//   T = log(n·dt / 1 s)          D = log ‖mean_i (p_i − p_1)‖
//   V = log mean_i ‖v_i‖         A = log mean_i ‖a_i‖
//   C = log mean_i ‖v_i × a_i‖   H = log mean_i h_i
// (logs of values + 1e-3). The paper's B_* are these unit choices (seconds,
// body heights); its W_* are 1 — the HMM's per-state covariances absorb the
// remaining scale. V, A, C use mean magnitudes rather than the magnitude of
// the summed vectors, which vanishes for strokes that return.
StatusOr<std::vector<KinematicSegment>> ComputeKinematicSegments(const motion::Clip& clip,
                                                                 const KinematicOptions& options = {});

// The segment holding time t (the nearest one outside the clip), for
// ascending times; one row of parameters per time.
Eigen::MatrixXd KinematicsAtTimes(const std::vector<KinematicSegment>& segments,
                                  const std::vector<double>& times_s);

}  // namespace kinemo::gesture
