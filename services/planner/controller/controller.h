// The Gesture Controller control layer (Gesture Controllers §7, §8,
// Appendix A): an immutable Controller built from a segmented motion library
// and an inference model's hidden states, the online Policy, and offline
// dynamic-programming synthesis.
//
// Time steps are frames of the library. The inference model's transition
// matrix T is per belief step (about one syllable, `belief_step_s`); per frame
// we use the "lazy" chain T_f = (1 − λ) I + λ T with λ = frame_time /
// belief_step_s (the same expected number of state changes per second), and
// P_n = T_f^n. The discount η is per belief step (η_f = η^λ per frame).
//
// Reduced value table (Appendix A). Decisions happen only at end points e =
// (a, f_k), f_k ∈ R_a ∪ {n_a − 1}. An action is: enter segment b at its first
// frame (cost S(e, b)), continue a to its next end point, or (with a pending
// keyword w) enter the stroke of a matching semantic gesture b at
// f'_start(e, b) ≤ fraction·n_b chosen by D_int. A block of L frames costs
// Σ_{g<L} η_f^g P_g δ; the value of an action is its block cost plus
// η_f^L · Σ_j P_L(j|i) min_actions V(·, e', j) at the end point e' it reaches:
//   V(b, e, i)      = S(e, b) + U(b, i) + [w: C_sem if b does not match w]
//   V(cont, e, i)   = Vc(e, i)
//   V(sem b, e, i)  = D_int(e, b, f'_start) + block + future in the table w = none
// U and Vc are the table; entry values are S + U. Value iteration runs to a
// tolerance (segments in parallel; within a segment end points are updated
// last to first). After convergence, entries (b, e) dominated for every state
// and every tone by another action at e are culled (§7.2); the policy only
// looks at the kept ones. Style (§8.2): per tone m, δ^m uses T_m·Y, and V =
// Σ_m d(m) V^m; culling keeps an entry unless it is dominated for all (m, i),
// so every d is served exactly.
//
// Gesture emphasis e ∈ [−1, 1] (planner.v1.StyleVector.gesture_emphasis):
// per tone m, two more tables "m:+" and "m:-" whose target is T_m·Y shifted
// on the log scales by ±s, with s_j = σ_j, the standard deviation of the
// library's own neutral segments on D, V, A, C and H (0 on T: emphasis
// changes how strongly a gesture is made, not how long). One σ means "as
// much stronger (weaker) than usual as this library's gestures typically
// differ from each other": the factor k_j = exp(σ_j) comes from the data the
// controller plays (docs/tones.md "Tones and the cube"), needs no constant, and asks for
// segments the library has. V = Σ_m d(m) ((1 − |e|) V^m + |e| V^{m:±}):
// weights stay non-negative, so culling (over all tables) still serves every
// (d, e) exactly, and e = ±1 is the tone mix with its targets shifted by ±s.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "common/motion/feet.h"
#include "common/motion/inertialize.h"
#include "common/motion/skeleton.h"
#include "common/status/cancel.h"
#include "common/status/status.h"
#include "services/planner/controller/expected_distance.h"
#include "services/planner/controller/segments.h"
#include "services/planner/controller/tones.h"
#include "services/planner/library/feet.h"

namespace kinemo::planner::controller {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// What the controller needs from the inference model.
struct StateModel {
  Eigen::VectorXd initial;                // S
  RowMatrix transition;                   // S × S, T(i, j) = P(j | i)
  std::vector<Vector6> means;             // S
  std::vector<Matrix6> covariances;       // S
  int num_states() const { return static_cast<int>(initial.size()); }
};
Status ValidateStateModel(const StateModel& m);

struct ControllerParams {
  double discount = 0.9;                     // η per belief step, (0, 1)
  double belief_step_s = 0.25;               // seconds per step of T
  double tolerance = 1e-4;                   // largest value change to stop
  int max_iterations = 1000;
  bool disable_culling = false;
  double semantic_cost = 50.0;               // C_sem of a segment not matching a pending keyword
  double semantic_start_max_fraction = 0.5;  // f'_start ≤ this · n_b
  std::vector<std::string> tones;            // empty = every tone of the library
  std::string neutral_tone = "neutral";
  // Tones estimated on another corpus (tones.h), applied about the library's
  // neutral mean; they join (or, by name, replace) the library's tones.
  std::vector<ToneTransfer> tone_transfers;
  int threads = 0;                           // 0 = hardware threads
  SegmentOptions segmentation;               // incl. interruption frames, weights
};
Status ValidateControllerParams(const ControllerParams& p);

struct BuildReport {
  double library_s = 0;
  int segments = 0;
  int end_points = 0;
  std::uint64_t entries_total = 0;  // normal entries (b, e) over all keyword states
  std::uint64_t entries = 0;        // kept (normal kept + continuations + semantic)
  double culled_fraction = 0;
  double train_s = 0;
  double segment_s = 0, delta_s = 0, value_iteration_s = 0, culling_s = 0;
  int iterations = 0;               // sweeps, summed over tables
  double final_change = 0;          // largest last change over tables
  std::vector<std::string> warnings;
};

// Stage name ("segments", "delta", "value_iteration", "culling"), fraction of
// the stage. Returning false cancels (CANCELLED).
using BuildProgress = std::function<bool(std::string_view stage, double fraction)>;

class Controller {
 public:
  static StatusOr<std::shared_ptr<const Controller>> Build(std::shared_ptr<const Library> library,
                                                           const StateModel& model,
                                                           const ControllerParams& params,
                                                           const BuildProgress& progress, BuildReport* report);

  const SegmentLibrary& segments() const { return *segments_; }
  std::shared_ptr<const SegmentLibrary> segment_library() const { return segments_; }
  const Library& library() const { return *segments_->library; }
  const ControllerParams& params() const { return params_; }
  const StateModel& state_model() const { return model_; }
  const BuildReport& report() const { return report_; }
  int num_states() const { return model_.num_states(); }
  int num_tones() const { return static_cast<int>(tones_.size()); }
  // Every table's tone, the emphasis tables included.
  const std::vector<std::string>& tones() const { return tones_; }
  // The tones a style may name (tones() without the emphasis tables).
  std::vector<std::string> style_tones() const;
  const std::vector<std::string>& keywords() const { return segments_->keywords; }
  int ToneIndex(std::string_view tone) const;      // -1 if absent
  // The gesture-emphasis table of tone m (an index into style_tones()) for
  // e > 0 ("<tone>:+") or e < 0 ("<tone>:-"), after the style tones' own;
  // −1 when the controller was built before emphasis existed.
  static bool IsEmphasisTone(std::string_view tone) { return tone.find(':') != std::string_view::npos; }
  int EmphasisIndex(int tone, double e) const;
  // Whether the controller has emphasis tables (built since they exist).
  bool HasEmphasis() const { return EmphasisIndex(0, 1) >= 0; }
  // s: the shift of the emphasised targets (e = +1) on the log scales
  // T D V A C H (zero without emphasis tables).
  Vector6 EmphasisShift() const;
  int KeywordIndex(std::string_view word) const;   // -1 if absent
  double frame_time_s() const { return segments_->library->frame_rate_hz > 0 ? 1.0 / segments_->library->frame_rate_hz : 1.0 / 30; }
  // Per-frame transition T_f (S × S).
  const RowMatrix& frame_transition() const { return frame_transition_; }
  // δ^m (segments × S).
  const RowMatrix& delta(int tone) const { return delta_[static_cast<size_t>(tone)]; }

  // A semantic action: from end point e into stroke segment b at `start`
  // (offset in b), reaching b's end point `h` (index into b.ends).
  struct SemanticEntry {
    int e = 0, segment = 0, start = 0, h = 0;
    double cost = 0;  // D_int(e, b, start)
  };
  // Keyword state w: 0 = none, 1 + k = keyword k pending.
  int num_keyword_states() const { return static_cast<int>(keywords().size()) + 1; }
  const RowMatrix& U(int tone, int w) const { return u_[Index(tone, w)]; }
  const RowMatrix& Vc(int tone, int w) const { return vc_[Index(tone, w)]; }
  // Semantic entries of keyword state w ≥ 1, grouped by end point (CSR).
  std::span<const SemanticEntry> SemanticEntries(int w, int e) const;
  // Values of semantic entry `index` (into the w's entry list) for tone m, S values.
  std::span<const double> SemanticValues(int tone, int w, int index) const;
  int SemanticBase(int w, int e) const { return sem_offsets_[static_cast<size_t>(w)][static_cast<size_t>(e)]; }
  // Kept normal entries at end point e in keyword state w.
  std::span<const int> Kept(int w, int e) const;
  bool Matches(int segment, int w) const;  // segment is a stroke for keyword w−1

  // Serialisation (the library is reloaded from `library_sources` by Load).
  // `inference_model_path` (optional) is recorded for `synthesize`.
  Status Save(const std::string& path, const std::vector<std::string>& library_sources,
              const std::string& inference_model_path = "") const;
  const std::string& inference_model_path() const { return inference_model_path_; }
  static StatusOr<std::shared_ptr<const Controller>> Load(const std::string& path);
  // Loads a controller on a library already loaded (e.g. the stored version
  // it depends on) instead of its recorded sources. FAILED_PRECONDITION when
  // the library does not segment to the segments the controller was built on
  // (other clips, order, frame rate or segmentation).
  static StatusOr<std::shared_ptr<const Controller>> Load(const std::string& path,
                                                          std::shared_ptr<const Library> library);

 private:
  friend class ControllerBuilder;
  friend struct ControllerFile;
  size_t Index(int tone, int w) const { return static_cast<size_t>(tone) * num_keyword_states() + w; }

  std::shared_ptr<const SegmentLibrary> segments_;
  std::string inference_model_path_;
  ControllerParams params_;
  StateModel model_;
  BuildReport report_;
  std::vector<std::string> tones_;
  std::vector<StyleTransform> transforms_;
  RowMatrix frame_transition_;
  std::vector<RowMatrix> delta_;              // per tone
  std::vector<RowMatrix> u_, vc_;             // per (tone, w)
  std::vector<std::vector<SemanticEntry>> sem_;          // per w
  std::vector<std::vector<int>> sem_offsets_;            // per w: E + 1
  std::vector<RowMatrix> sem_values_;                    // per (tone, w): entries × S
  std::vector<std::vector<int>> kept_offsets_, kept_;    // per w
};

// ---------------------------------------------------------------------------
// Online policy: α_t, keyword, style d → next segment and frame. Buffers are
// allocated at construction; Decide/Advance/SetBelief allocate nothing. One
// per stream (not thread-safe); the controller must outlive it.
struct Decision {
  int segment = 0;
  int start = 0;             // first frame, offset in the segment
  int end_point = 0;         // the end point this play reaches (global index)
  bool continuation = false; // continues the current segment
  bool interrupted = false;  // left the previous segment before its end
  int keyword = -1;          // keyword served (index), -1 if none
  double expected_cost = 0;  // Σ_m d(m) Σ_i α(i) V^m(choice, e, i)
};

class Policy {
 public:
  // A run is the library material played since the policy last *chose* an
  // entry: the chosen play and the true successors it continues into (whose
  // transition costs nothing). A run is not interrupted before it has shown
  // `min_play_s` (a keyword may still interrupt it); at a segment's last
  // frame the policy chooses by value as always. Choosing greedily at every
  // end point (end points are ~0.1-0.3 s apart) jumped again before the
  // previous jump's blend had finished, and the overlapping blends damped the
  // motion toward stillness (docs/evaluation.md). The age is the run's, not
  // the segment's: counted per segment, a chain of short segments (each one
  // young) never grew old, the run cap never acted and the chain was replayed
  // whole. 1 s (was 0.6 s): with the memory below, 0.6 s jumped 69 times a
  // minute on held-out BEAT2 speech (fold 2) and moved FID_k from 48 to 60;
  // 1 s: 62 jumps a minute, FID_k 50 (docs/evaluation.md). 0 = no minimum.
  static constexpr double kDefaultMinPlaySeconds = 1.0;
  // Choice, not playback: a run ends after `max_run_s`: past it, at the next
  // end point, the policy neither continues the segment nor enters its
  // successor but chooses another entry by value (a pending keyword still
  // decides as before). Without it the zero-cost successors made the policy
  // replay the library: 77 % of a live output on held-out BEAT2 speech lay in
  // near-copies of the library over 2 s (docs/evaluation.md). 0 = no limit.
  static constexpr double kDefaultMaxRunSeconds = 1.5;
  // A short memory: a segment shown in the last `recent_s` is not entered
  // again (its successor included), unless every entry was (a pending keyword
  // decides as before). Without it the policy cycled through the same few
  // segments: a 5-frame segment and its predecessor alternated for 7 s (a
  // tremor), chains of three segments came back every few seconds
  // (docs/evaluation.md, "Online policy: choice instead of replay"). 0 = none.
  static constexpr double kDefaultRecentSeconds = 4.0;
  explicit Policy(const Controller& controller, double min_play_s = kDefaultMinPlaySeconds,
                  double max_run_s = kDefaultMaxRunSeconds, double recent_s = kDefaultRecentSeconds);
  // α (S values, ≥ 0, renormalised). INVALID_ARGUMENT naming `probabilities`.
  Status SetBelief(std::span<const double> probabilities);
  // One frame without observation: α ← α T_f.
  void Advance();
  // Weights per tone (num_tones values, ≥ 0, not all 0; normalised).
  Status SetStyle(std::span<const double> weights);
  // Keyword k pending (−1 = none). INVALID_ARGUMENT if out of range.
  Status SetKeyword(int keyword);
  int pending_keyword() const { return keyword_; }
  // First play of a stream: the best segment start under α.
  Decision Start();
  // The next play at end point e (the current segment has just shown its
  // frame there). Resets the pending keyword when it is served.
  Decision Decide(int e);
  std::span<const double> belief() const { return {alpha_.data(), static_cast<size_t>(alpha_.size())}; }

 private:
  // Frames of the decision just made become the current block (the clock).
  void BeginBlock(const Decision& d);
  const Controller& c_;
  Eigen::VectorXd alpha_, tmp_, style_;
  int keyword_ = -1;
  int min_play_frames_ = 0;
  int max_run_frames_ = 0;
  int recent_frames_ = 0;
  int play_segment_ = -1, play_start_ = 0;  // the current play: its segment and first frame
  int run_base_ = 0;  // frames of the current run before the current play
  // The memory: frames shown so far (counted at decisions), the block being
  // played (segment, first frame), and per segment the clock when it was last
  // shown.
  std::int64_t clock_ = 0;
  int block_segment_ = -1, block_start_ = 0;
  std::vector<std::int64_t> last_shown_;
};

// ---------------------------------------------------------------------------
// The nominal length of a transition between segments (FrameAssembler's
// blend_frames when 0 is given). Its quintic's jerk falls with the cube of the
// length: on BEAT2 (GC, leave one take out, the two folds) 0.2 s gave wrist
// jerk 79 / 78 m/s³, 0.4 s 74 / 57, 0.6 s 68 / 51, 0.8 s 68 / 52 with the
// ankle lifted in 4.4 % of fold 1's frames (real motion: 43-57, 0.2-3.3 %).
inline constexpr double kTransitionS = 0.6;
inline int DefaultBlendFrames(double frame_time_s) {
  return std::max(1, static_cast<int>(std::lround(kTransitionS / frame_time_s)));
}

// Continuous output: a frame stream from plays of segments. A frame that does
// not follow the previous one in its clip starts a transition, inertialized
// (common/motion/inertialize.h): the difference between the motion shown and
// the new segment (per joint rotation, root position) and its velocity and
// acceleration decay to zero along a quintic over `blend_frames` frames
// (kTransitionS by default), longer (up to 4x) when the two poses are far
// apart, so every joint keeps its velocity and acceleration across the join.
// The new segment is shifted horizontally to stand where the old one would
// have stood next. The stream
// begins at the library's rest pose (SegmentLibrary::rest: hands low and
// still) and moves into the first segment over `start_frames`, the first
// segment easing in from standstill (its playback speed rises from 0 to 1
// along a smoothstep over those frames, so it runs start_frames / 2 frames
// behind until the next jump: a segment that begins mid-stroke otherwise
// met the still rest pose with its full speed); NextRest() returns to it. Then, unless `feet.enabled` is false, the feet are planted
// (common/motion/feet.h, with the library's scale and ground:
// LibraryFootPlantParams): the stream of frames goes through one
// FootPlanter, so offline synthesis, online runs and the Control stream plant
// alike. Allocation-free after construction.
class FrameAssembler {
 public:
  // start_frames: frames from the rest pose into the first segment (< 0 =
  // 0.5 s, 0 = the first segment's first frame as it is).
  FrameAssembler(const SegmentLibrary& segments, int blend_frames,
                 const motion::FootPlantParams& feet = motion::StandingFootPlantParams(), int start_frames = -1);
  ~FrameAssembler();
  // Writes the next output frame showing frame `f` of segment `segment`.
  void Next(int segment, int f, std::span<double> out);
  // Writes the next output frame on the way back to the rest pose: the first
  // call starts a transition of `frames` frames from the motion shown to the
  // rest pose (standing where the motion stands), later calls continue it and
  // then hold the pose.
  void NextRest(int frames, std::span<double> out);
  // Largest joint angular speed between consecutive assembled frames (before
  // foot planting) inside a transition (from its jump to its end), and
  // elsewhere, deg/s.
  double max_transition_dps() const { return max_transition_dps_; }
  double max_inside_dps() const { return max_inside_dps_; }
  int transitions() const { return transitions_; }
  // Whether feet are planted; when asked for but impossible (a skeleton
  // without legs or root position channels), feet_status() says why.
  bool plants_feet() const { return planter_ != nullptr; }
  const Status& feet_status() const { return feet_status_; }

 private:
  // Transition frames for a jump from the frame shown (prev_) to `to`.
  int TransitionFrames(std::span<const double> to) const;
  // Starts the decay into frame g of `clip` (its frames g-1..g-3 as the new
  // motion's past) over `frames`, the motion shown carried over at most
  // twice the nominal length.
  void StartTransition(const motion::Clip& clip, int g, int frames);
  // The rest pose standing where frame (clip, frame) + offset_ stands, into rest_.
  void RestAt(int clip, int frame);
  void Finish(bool transition, std::span<double> out);

  const SegmentLibrary& s_;
  const motion::Skeleton& skel_;
  int blend_frames_;
  int start_frames_;
  int frames_out_ = 0;
  int cur_clip_ = -1, cur_frame_ = -1;
  bool resting_ = false;  // NextRest has started
  Eigen::Vector3d offset_ = Eigen::Vector3d::Zero();
  // The first segment's eased start: frame of its clip shown at output
  // frame 0; true until the first jump.
  int ease_first_ = 0, ease_shown_ = 0;  // and the frame shown last
  bool easing_ = false;
  std::vector<double> prev_, a_, t1_, t2_, t3_, rest_;
  motion::Inertializer inertializer_;
  // Local rotation of every joint in the previous and the current output
  // frame (the angular-speed statistics compare them: each frame's rotations
  // are computed once, not once per comparison).
  std::vector<Eigen::Matrix3d> prev_rot_, cur_rot_;
  // The joints a transition's length is measured on: the chains from the
  // root to the head, the wrists and the ankles (not fingers, eyes, jaw or
  // toes, whose pose differences are large and quick to blend).
  std::vector<int> gap_joints_;
  int transitions_ = 0;
  double max_transition_dps_ = 0, max_inside_dps_ = 0;
  std::unique_ptr<motion::FootPlanter> planter_;
  Status feet_status_;
  StanceLocator stance_;  // segments are joined where the body stands
};

// ---------------------------------------------------------------------------
// Offline synthesis (§7.1): DP over smoothed beliefs γ_t.
struct BeliefSpan {
  double start_s = 0, end_s = 0;
  std::vector<double> probabilities;
};
struct KeywordEvent {
  std::string word;
  double start_s = 0, end_s = 0;
};
struct SegmentPlayOut {
  int segment = 0;
  int first = 0, last = 0;  // offsets in the segment, inclusive
  double start_s = 0, end_s = 0;
  bool interrupted = false;
  std::string keyword;
};
struct SynthesisResult {
  motion::Clip clip;
  std::vector<SegmentPlayOut> plays;
  bool feet_planted = false;  // see FrameAssembler::plants_feet
  std::string feet_note;      // why not, when asked for
  double max_transition_dps = 0;
  double max_inside_dps = 0;
  double library_p99_dps = 0;
  double total_cost = 0;
  double compute_s = 0;
};
struct SynthesisOptions {
  double duration_s = 0;                     // 0 = end of the last belief
  std::vector<double> style;                 // per tone; empty = neutral (or the first tone)
  std::vector<KeywordEvent> keywords;        // unknown words are ignored
  double keyword_deadline_s = 0.3;           // stroke must be on by word end + this
  int blend_frames = 0;                      // 0 = kTransitionS
  double max_duration_s = 600;
  motion::FootPlantParams feet = motion::StandingFootPlantParams();  // planted feet (on by default)
  double min_play_s = Policy::kDefaultMinPlaySeconds;  // RunOnline: see Policy
  // Synthesize stops with its status (DEADLINE_EXCEEDED or CANCELLED,
  // "synthesis: ...") once it is stopped; null = never.
  const CancelToken* cancel = nullptr;
  // Longest run of unbroken library material (Policy::kDefaultMaxRunSeconds):
  // the online policy's limit, and in the offline DP a path may not extend a
  // run past it (each cell keeps the run length of its best path); 0 = none.
  double max_run_s = Policy::kDefaultMaxRunSeconds;
  // Memory of segments shown (Policy::kDefaultRecentSeconds): the online
  // policy's, and in the offline DP an entry may not go to a segment its path
  // showed in the last recent_s (each cell keeps its best path's records, as
  // it keeps the run; the DP is then no longer exact, as with max_run_s).
  // Without it the DP found one cheap segment and came back to it: 25 of 51
  // plays, 58 % of the output, on held-out BEAT2 speech (docs/evaluation.md).
  // 0 = none.
  double recent_s = Policy::kDefaultRecentSeconds;
  // The motion begins at the library's rest pose (moving into the first
  // segment over start_s) and returns to it: the last end_s seconds are the
  // transition to rest (its first 70 %) and the pose held; 0 = off.
  double start_s = 0.5;
  double end_s = 1.3;
};
StatusOr<SynthesisResult> Synthesize(const Controller& controller, const std::vector<BeliefSpan>& beliefs,
                                     const SynthesisOptions& options);

// Online synthesis over a belief sequence (for tests and the bench): feeds
// α_t at the steps' times and keywords at their end times into a Policy and
// plays its decisions. decide_us receives each decision's wall time.
StatusOr<SynthesisResult> RunOnline(const Controller& controller, const std::vector<BeliefSpan>& beliefs,
                                    const SynthesisOptions& options, std::vector<double>* decide_us);

// Baseline for evaluations (docs/evaluation.md): random segments of the same
// library in random order, with the same frame assembly as Synthesize
// (blending, planted feet). The first segment is drawn at random; at each
// segment's last frame another segment (never the one just played, unless it
// is the only one) is drawn uniformly and played from its first frame to its
// last, so the plays have the library's segment lengths. The beliefs only set
// the duration (as in Synthesize); keywords and style are ignored. The same
// seed gives the same motion.
StatusOr<SynthesisResult> SynthesizeRandom(const Controller& controller, const std::vector<BeliefSpan>& beliefs,
                                           const SynthesisOptions& options, std::uint64_t seed);

// Style vector (one weight per table, num_tones() values) from tone weights
// (by name; empty = neutral only) and a gesture emphasis e ∈ [−1, 1] (see
// the header comment): INVALID_ARGUMENT naming style.tone_weights (unknown
// or reserved tone, negative, NaN, sum 0) or style.gesture_emphasis (NaN,
// out of range). A controller built before emphasis existed has no emphasis
// tables: e then has no effect (HasEmphasis() says which; the planner logs
// it), so a cube turned during a live stream never ends the stream.
StatusOr<std::vector<double>> StyleFromWeights(const Controller& controller,
                                               const std::vector<std::pair<std::string, double>>& weights,
                                               double gesture_emphasis = 0);

}  // namespace kinemo::planner::controller
