// Numerical evaluation of generated gesture motion against natural
// references (`kinemo motion compare`, docs/evaluation.md), in the manner of
// the GENEA challenges' numerical evaluations and AIST++'s FID_k.
// Plain C++ (Eigen); no learned encoder, no gRPC.
//
// Every clip is reduced to a RoleTrack: the world positions, in metres, of
// the joints that play a role in every skeleton (pelvis, head, both
// shoulders, elbows and wrists; body_regions.h FindKeyJoints: the wrist is
// the top of the hand region, the elbow its parent, the shoulder the elbow's
// parent), resampled to 30 fps. So Bandai (22 joints), CMU and SMPL-X (55)
// outputs compare with each other.
//
// Measures (all in metres and seconds):
//   hellinger_speed/accel   Hellinger distance H = sqrt(1 − Σ sqrt(p_i q_i))
//       between the histograms of the wrists' world speed (bins of 0.05 m/s
//       over [0, 3) m/s, one overflow bin) and acceleration (0.5 m/s² over
//       [0, 30), overflow) of the generated clip and of the references
//       (both wrists pooled; forward differences at 30 fps). Also for the
//       elbows (hellinger_*_elbows).
//   fd_kinetic              Fréchet distance between Gaussians fitted to
//       kinetic feature vectors of 1 s windows (hop 0.5 s) of the generated
//       clip and of the references; 24 hand-made features, each z-scored by
//       the references' mean and standard deviation (KineticFeatureNames()).
//   jerk/accel means        mean magnitude of the wrists' third / second
//       difference of world position (m/s³, m/s²).
//   hand speed              mean and p95 of the wrists' world speed.
//   hands_moving_fraction   frames where either wrist moves faster than
//       0.15 m/s relative to the pelvis (the gesture module's hold speed).
//   hands_raised_fraction   frames where either wrist is higher than its
//       shoulder minus 0.15 m (a hand near or above shoulder height: waving,
//       hand on the head, pointing up).
//   beat_consistency        AIST++ beat alignment: mean over the audio's
//       syllable onsets of exp(−d² / 2σ²), d the distance to the nearest
//       kinematic beat, σ = 0.1 s. Kinematic beats are apexes: the first
//       speed minimum (relative to the pelvis, 3-frame smoothed) after a
//       stroke peak of one wrist ≥ 0.3 m/s. A weak signal: speech has ~4
//       onsets per second, so a busy random motion scores well;
//       beat_consistency_chance is the same score with the beats shifted by
//       2..10 s (circularly), the level of motion unrelated to the speech.
//   accent_sync_fraction    the thesis' rule (§4.4.3): the share of pitch
//       accents with an apex inside the synchrony window, PAPT − apex in
//       [−0.03, 0.22] s; with its chance level likewise.
//   longest_copy_s          the longest run of consecutive output frames that
//       equal consecutive frames of one library clip (every role joint within
//       1 cm of the library's, relative to the pelvis); and its share of the
//       output (longest_copy_fraction), the share of output frames in
//       copied runs of ≥ 1 s (copied_fraction) and of output frames equal to
//       some library frame at all (copy_frame_fraction; the rest are blends,
//       warps or other motion).
//   foot slide              (added by the CLI) motion_check.h's
//       foot_slide_p95_m_s, on the clip as given, not resampled.
//   max_joint_speed_m_s     the fastest role joint (or foot) in any frame.
#pragma once

#include <array>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::evaluation {

enum Role : int {
  kPelvis = 0,
  kHead,
  kLeftShoulder,
  kRightShoulder,
  kLeftElbow,
  kRightElbow,
  kLeftWrist,
  kRightWrist,
  kLeftFoot,
  kRightFoot,
};
inline constexpr int kNumRoles = 10;

// Metres per unit snapped to the nearest standard unit (mm, cm, inch, foot,
// m) when the estimate is within 25 % of it, else the estimate (body-height
// estimates are off by the speaker's size; files are written in a unit).
double SnapMetersPerUnit(double estimate);

struct RoleTrack {
  double frame_time_s = 1.0 / 30;
  // frames × 3·kNumRoles: role r's x y z (metres, world, y up) in columns 3r..3r+2.
  Eigen::MatrixXd p;
  int num_frames() const { return static_cast<int>(p.rows()); }
  Eigen::Vector3d At(int f, int role) const { return p.block<1, 3>(f, 3 * role).transpose(); }
};

// The role joints of a clip, world positions × meters_per_unit (> 0),
// resampled to `fps` unless the clip's rate is within 1 % of it.
// FAILED_PRECONDITION when the skeleton has no head, hands or feet.
StatusOr<RoleTrack> ExtractRoleTrack(const motion::Clip& clip, double meters_per_unit, double fps = 30);

struct CompareOptions {
  double speed_bin_m_s = 0.05;
  int speed_bins = 60;  // + 1 overflow bin
  double accel_bin_m_s2 = 0.5;
  int accel_bins = 60;
  double window_s = 1.0;
  double hop_s = 0.5;
  double moving_speed_m_s = 0.15;
  double raised_below_shoulder_m = 0.15;
  double stroke_peak_m_s = 0.3;
  double beat_sigma_s = 0.1;
  double sync_min_s = -0.03;  // PAPT − apex
  double sync_max_s = 0.22;
  double copy_tolerance_m = 0.01;
  double copy_min_run_s = 1.0;  // for copied_fraction
};

// Times of the speech (from the prosody analysis).
struct AudioEvents {
  std::vector<double> onsets_s;   // syllable onsets
  std::vector<double> accents_s;  // pitch accents (PAPT)
};

// Measures of one clip on its own (no reference).
struct ClipMeasures {
  double duration_s = 0;
  double jerk_mean_m_s3 = 0;
  double accel_mean_m_s2 = 0;
  double hand_speed_mean_m_s = 0;
  double hand_speed_p95_m_s = 0;
  double hands_moving_fraction = 0;
  double hands_raised_fraction = 0;
  double hand_height_mean_m = 0;  // wrists above the pelvis
  double max_joint_speed_m_s = 0;
  int kinematic_beats = 0;
  // With audio:
  double beat_consistency = 0;
  double beat_consistency_chance = 0;
  double accent_sync_fraction = 0;
  double accent_sync_chance = 0;
  int accents = 0;
};

struct Comparison {
  ClipMeasures generated;
  ClipMeasures reference;  // the references' measures (frame-weighted mean)
  bool has_audio = false;
  double hellinger_speed = 0, hellinger_accel = 0;
  double hellinger_speed_elbows = 0, hellinger_accel_elbows = 0;
  double fd_kinetic = 0;
  int windows = 0, reference_windows = 0;
  bool has_library = false;
  double longest_copy_s = 0;
  double longest_copy_fraction = 0;
  double copied_fraction = 0;
  double copy_frame_fraction = 0;  // output frames equal to some library frame
};

ClipMeasures MeasureClip(const RoleTrack& track, const AudioEvents* audio, const CompareOptions& options = {});

// INVALID_ARGUMENT when there is no reference or a clip is shorter than one
// window. `library` may be empty.
StatusOr<Comparison> Compare(const RoleTrack& generated, std::span<const RoleTrack> references,
                             const AudioEvents* audio, std::span<const RoleTrack> library,
                             const CompareOptions& options = {});

// ---- Parts, exposed for tests.
double HellingerDistance(std::span<const double> p, std::span<const double> q);  // normalises both
// Histogram of values: `bins` of `width` from 0, the last bin taking the rest.
std::vector<double> Histogram(std::span<const double> values, double width, int bins);
// ‖μ1 − μ2‖² + tr(Σ1 + Σ2 − 2 (Σ1 Σ2)^½).
double FrechetDistance(const Eigen::VectorXd& mu1, const Eigen::MatrixXd& s1, const Eigen::VectorXd& mu2,
                       const Eigen::MatrixXd& s2);
// Rows: windows; columns: KineticFeatureNames().
Eigen::MatrixXd KineticFeatures(const RoleTrack& track, const CompareOptions& options = {});
const std::vector<std::string>& KineticFeatureNames();
// Apex times (s) of the strokes of either wrist.
std::vector<double> KinematicBeats(const RoleTrack& track, const CompareOptions& options = {});
// Mean over `events` of exp(−d²/2σ²), d to the nearest beat; 0 without events or beats.
double BeatAlignment(std::span<const double> events, std::span<const double> beats, double sigma_s);
// Share of accents with a beat b such that accent − b ∈ [min_s, max_s].
double SyncFraction(std::span<const double> accents, std::span<const double> beats, double min_s, double max_s);
// Longest run (frames) of `track` equal to consecutive frames of one library
// track; `run_lengths` (optional) receives the run ending at each frame.
int LongestCopy(const RoleTrack& track, std::span<const RoleTrack> library, double tolerance_m,
                std::vector<int>* run_lengths = nullptr);

}  // namespace kinemo::evaluation
