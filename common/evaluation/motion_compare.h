// Numerical evaluation of generated gesture motion against natural
// references (`kinemo motion compare`, docs/evaluation.md): the field's
// published measures (GENEA's speed/acceleration Hellinger distances,
// AIST++'s FID_k, BEAT/EMAGE's beat consistency and L1 diversity), a
// near-copy detector for library playback, and kinemo's own measures, named
// apart. Plain C++ (Eigen); no learned encoder, no gRPC.
//
// Every clip is reduced to a RoleTrack: the world positions, in metres, of
// the joints that play a role in every skeleton (pelvis, head, both
// shoulders, elbows, wrists, hips, knees and ankles; body_regions.h
// FindKeyJoints: the wrist is the top of the hand region, the elbow its
// parent, the shoulder the elbow's parent; the ankle is the foot joint, the
// knee its parent, the hip the knee's parent), resampled to 30 fps. So
// Bandai (22 joints), CMU and SMPL-X (55) outputs compare with each other.
//
// Published measures (definitions, citations and the reference
// implementations followed: docs/evaluation.md):
//   genea_hellinger_speed/accel  GENEA numerical evaluation: Hellinger
//       distance between the histograms of the wrists' moving distance per
//       frame (first difference, cm) and of its second difference (cm), bins
//       of 0.05 cm over [0, 49] cm (GENEA's HMD), per-joint histograms of
//       both wrists summed, output against all references pooled.
//   fid_k                    AIST++ / Bailando FID_k: per role joint the
//       average horizontal and vertical kinetic energy and the average energy
//       expenditure (fairmotion's KineticFeatures, velocities averaged over
//       ±2 frames) of each 2 s window (hop 1 s; 42 features), z-scored by
//       the mean and standard deviation of the windows of both clips pooled,
//       Fréchet distance (fid_k_bailando: z-scored by the references' windows
//       alone, as Bailando's code does).
//   beat_consistency         BEAT / EMAGE BC: audio onsets (librosa's
//       onset_detect at 16 kHz, hop 512: AudioOnsets()), motion beats per
//       upper-body joint (local minima of speed over ±7 frames, speed above
//       0.1× the joint's mean speed in the references), mean over onsets of
//       exp(−d²/2σ²), σ = 0.3 s, averaged over the joints.
//   l1_div                   EMAGE / TalkSHOW L1 diversity: Σ over the role
//       joints' coordinates (relative to the pelvis, metres) of the mean
//       absolute deviation from their mean over the clip.
// Issue-defined measures:
//   near_copy_share_over_2s, longest_near_copy_s   NearCopies(): runs of
//       output frames within 3 cm mean joint error of library frames whose
//       index advances by 0, 1 or 2 per output frame (blends, time warps).
//   library_repeat_share     NearCopies(): output frames inside a run of
//       0.5 s or more that plays library frames on (3 cm, steps 0-2, at least
//       half a library frame per output frame) which a run played 1 s or
//       more before (library material shown again: a loop of short plays
//       that no near copy over 2 s finds).
//   ankle_lift_share         frames with an ankle more than 0.10 m above its
//       lowest height in the clip.
// kinemo's own measures (all in metres and seconds):
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
//   kinemo_beat_alignment   AIST++-style beat alignment on the speech's
//       syllable onsets: mean over the onsets of exp(−d² / 2σ²), d the
//       distance to the nearest kinematic beat, σ = 0.1 s. Kinematic beats
//       are apexes: the first speed minimum (relative to the pelvis, 3-frame
//       smoothed) after a stroke peak of one wrist ≥ 0.3 m/s. A weak signal:
//       speech has ~4 onsets per second, so a busy random motion scores
//       well; *_chance is the same score with the beats shifted by 2..10 s
//       (circularly), the level of motion unrelated to the speech.
//   accent_sync_fraction    the thesis' rule (§4.4.3): the share of pitch
//       accents with an apex inside the synchrony window, PAPT − apex in
//       [−0.03, 0.22] s; with its chance level likewise.
//   longest_copy_s          the longest run of consecutive output frames that
//       equal consecutive frames of one library clip (every upper-body role
//       joint within 1 cm of the library's, relative to the pelvis); and its
//       share of the output (longest_copy_fraction), the share of output
//       frames in copied runs of ≥ 1 s (copied_fraction) and of output frames
//       equal to some library frame at all (copy_frame_fraction).
//   envelope_correlation    Pearson correlation of the 0.5 s hand-speed
//       envelopes of the output and of the first reference over their common
//       length (HandSpeedEnvelope); for matched / mismatched tests.
//   speech_envelope_correlation   the same between the output's hand-speed
//       envelope and the speech's loudness envelope (LoudnessEnvelope).
//   foot slide              (added by the CLI) motion_check.h's
//       foot_slide_p95_m_s, on the clip as given, not resampled.
//   max_joint_speed_m_s     the fastest role joint (head to ankles) in any frame.
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
  kLeftFoot,  // the ankle (FindKeyJoints' foot)
  kRightFoot,
  kLeftKnee,  // the ankle's parent
  kRightKnee,
  kLeftHip,  // the knee's parent
  kRightHip,
};
inline constexpr int kNumRoles = 14;
// The roles of the upper body whose pose the copy detectors compare: head,
// shoulders, elbows, wrists (kHead..kRightWrist).
inline constexpr int kFirstUpperRole = kHead;
inline constexpr int kNumUpperRoles = kRightWrist - kHead + 1;

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
  // kinemo's own measures.
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
  double envelope_s = 0.5;      // hand-speed envelope bins
  // GENEA: bins of the moving distance per frame and of its second difference.
  double genea_bin_cm = 0.05;
  double genea_max_cm = 49;
  // AIST++ FID_k.
  double fid_window_s = 2.0;
  double fid_hop_s = 1.0;
  int kinetic_average_frames = 2;  // fairmotion's sliding_window (± frames)
  // BEAT / EMAGE beat consistency.
  double bc_sigma_s = 0.3;
  int bc_order = 7;                 // a beat is below its 7 neighbours on each side
  double bc_speed_threshold = 0.1;  // × the joint's mean speed in the references
  // Near copies.
  double near_copy_tolerance_m = 0.03;  // mean over the upper-body joints
  int near_copy_max_step = 2;           // library frames per output frame: 0..2
  double near_copy_min_s = 2.0;         // runs longer than this
  double repeat_gap_s = 1.0;            // library material shown again after this: a repeat
  // Ankle lift.
  double ankle_lift_m = 0.10;
};

// Times of the speech (from the prosody analysis and AudioOnsets()).
struct AudioEvents {
  std::vector<double> onsets_s;   // syllable onsets (kinemo_beat_alignment)
  std::vector<double> accents_s;  // pitch accents (PAPT)
  std::vector<double> audio_onsets_s;  // librosa-style onsets (beat_consistency)
  // Loudness of the speech in consecutive bins of CompareOptions::envelope_s
  // (LoudnessEnvelope); empty: no speech_envelope_correlation.
  std::vector<double> loudness_db;
};

// Measures of one clip on its own (no reference).
struct ClipMeasures {
  double duration_s = 0;
  double jerk_mean_m_s3 = 0;
  double knee_jerk_mean_m_s3 = 0;  // the knees' third difference (legs that jitter)
  double accel_mean_m_s2 = 0;
  double hand_speed_mean_m_s = 0;
  double hand_speed_p95_m_s = 0;
  double hands_moving_fraction = 0;
  double hands_raised_fraction = 0;
  double hand_height_mean_m = 0;  // wrists above the pelvis
  double max_joint_speed_m_s = 0;
  int kinematic_beats = 0;
  double l1_div = 0;
  double ankle_lift_share = 0;
  // With audio:
  double kinemo_beat_alignment = 0;
  double kinemo_beat_alignment_chance = 0;
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
  double genea_hellinger_speed = 0, genea_hellinger_accel = 0;
  // NaN when a clip has fewer than two FID windows (3 s).
  double fid_k = 0;           // features z-scored by both clips' windows pooled
  double fid_k_bailando = 0;  // z-scored by the references' windows (Bailando)
  int fid_windows = 0, fid_reference_windows = 0;
  // BEAT/EMAGE beat consistency of the output and of the references (their
  // mean), with audio; *_chance: the beats shifted circularly by 2..10 s.
  double beat_consistency = 0, beat_consistency_chance = 0;
  double reference_beat_consistency = 0, reference_beat_consistency_chance = 0;
  int audio_onsets = 0;
  double envelope_correlation = 0;  // with the first reference
  // Hand-speed envelope against the speech's loudness envelope (with audio):
  // of the output and of the first reference.
  double speech_envelope_correlation = 0, reference_speech_envelope_correlation = 0;
  bool has_library = false;
  double longest_copy_s = 0;
  double longest_copy_fraction = 0;
  double copied_fraction = 0;
  double copy_frame_fraction = 0;  // output frames equal to some library frame
  double near_copy_share_over_2s = 0;
  double longest_near_copy_s = 0;
  double library_repeat_share = 0;  // NearCopyResult::frames_repeated / output frames
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

// GENEA's histogram of moving distance: per frame, the distance (cm) a role
// moved since the previous frame (k = 1) or the norm of its second difference
// (k = 2); Histogram of those values with bins of `bin_cm` over
// [0, max_cm], values beyond dropped (numpy.histogram's edges: the last bin
// includes max_cm). One histogram per role, summed.
std::vector<double> GeneaHistogram(const RoleTrack& track, std::span<const int> roles, int k, double bin_cm,
                                   double max_cm);

// fairmotion / AIST++ kinetic features of frames [first, first + count) of a
// track taken as one clip: for each role in `roles`, the average horizontal
// kinetic energy, the average vertical kinetic energy and the average energy
// expenditure (3 per role, in that order; m²/s², m²/s², m/s²).
Eigen::VectorXd AistKineticFeatures(const RoleTrack& track, int first, int count, std::span<const int> roles,
                                    int average_frames = 2);
// The roles FID_k uses: every role (pelvis to hips).
std::span<const int> FidRoles();

// BEAT/EMAGE motion beats of one joint: the frames (as seconds, frame /
// fps) whose speed (central differences; forward and backward at the ends)
// is below that of the `order` frames on each side and above
// `threshold_m_s`.
std::vector<double> EmageMotionBeats(const RoleTrack& track, int role, int order, double threshold_m_s);
// EMAGE's GAHR: mean over `onsets` of exp(−d²/2σ²), d the distance to the
// nearest beat; 0 without onsets or beats.
double GaussianAlignment(std::span<const double> beats, std::span<const double> onsets, double sigma_s);
// The roles of the beat consistency: head, shoulders, elbows, wrists.
std::span<const int> BeatRoles();
// Mean speed (m/s, central differences) of a role.
double MeanSpeed(const RoleTrack& track, int role);

// EMAGE's L1 diversity of the role joints relative to the pelvis (metres):
// Σ over coordinates of the mean over frames of |x − mean(x)|.
double L1Diversity(const RoleTrack& track);

// Share of frames with an ankle more than `lift_m` above its lowest height
// in the clip.
double AnkleLiftShare(const RoleTrack& track, double lift_m);

// Hand-speed envelope: the mean speed of both wrists relative to the pelvis
// in consecutive bins of `bin_s` (the last partial bin dropped).
std::vector<double> HandSpeedEnvelope(const RoleTrack& track, double bin_s);
// Loudness envelope of speech: 20 log10 of the RMS in consecutive bins of
// `bin_s` (the last partial bin dropped), floored 60 dB below the loudest bin.
std::vector<double> LoudnessEnvelope(std::span<const float> samples, int sample_rate_hz, double bin_s);
// Pearson correlation over the common length; 0 when either is constant or
// shorter than 3 values.
double PearsonCorrelation(std::span<const double> a, std::span<const double> b);

// Near copies of a library: runs of consecutive output frames f whose
// upper-body pose (roles kHead..kRightWrist relative to the pelvis, turned
// so that the hips face one way) is within `tolerance_m` mean joint error of
// library frames g(f) of one clip, g advancing by 0..max_step frames per
// output frame (copies, blends close to one side, slowed or sped-up playback).
struct NearCopyResult {
  std::vector<int> run_lengths;  // per output frame: the longest run ending there
  int longest = 0;               // frames
  int frames_in_long_runs = 0;   // output frames inside runs longer than min_frames
  int candidate_pairs = 0;       // (output, library) frame pairs within tolerance
  // Output frames inside a run of repeat_gap / 2 frames or more that plays
  // the library on (at least half a library frame per output frame) over
  // library frames a run played repeat_gap frames or more before: the same
  // material shown again (a loop), however short each showing.
  int frames_repeated = 0;
};
NearCopyResult NearCopies(const RoleTrack& track, std::span<const RoleTrack> library, double tolerance_m,
                          int max_step, int min_frames, int repeat_gap = 30);

// Audio onsets as librosa.onset.onset_detect (librosa 0.10 defaults; BEAT /
// EMAGE call it on 16 kHz audio with hop 512): onset strength = mean over 128
// Slaney mel bands (n_fft 2048, Hann, centred, power 2, dB with top_db 80) of
// the positive first difference; normalised to [0, 1]; peaks = frames at least
// 0.07 above the mean of the 3 frames before to 3 after (librosa's
// peak_pick, its pre/post max and wait windows from 30 ms at `sample_rate_hz`).
// Returns seconds (frame × hop / rate).
StatusOr<std::vector<double>> AudioOnsets(std::span<const float> samples, int sample_rate_hz);

}  // namespace kinemo::evaluation
