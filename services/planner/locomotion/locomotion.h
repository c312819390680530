// Body Part Motion Graphs (thesis ch. 3): locomotion transitions composed of
// one motion graph per body part, against the standard motion graph (SMG,
// one part). Plain C++, no gRPC.
//
//  - Kinematic chains (Table 3.1) from the skeleton's body-region map: head,
//    trunk, upper right, upper left, lower (the two leg chains, always
//    together). The hips joint (the common ancestor of head and feet) and its
//    ancestors carry the root motion and belong to the lower chain.
//  - Split profiles (Fig. 3.13): SMG, SP2, SP3a, SP3b, SP4a, SP4b, SP5, or
//    custom ones.
//  - Distance (Lee et al. 2002, eq. 2.2, orientation term): d(a, b) =
//    Σ_k w_k ‖log(q_b,k⁻¹ q_a,k)‖² over weighted joints, local rotations
//    (the hips' world rotation without its heading). Joint weights (§3.4):
//    0.3 lower back and forearms, 0.5 neck, 0.7 arms, 1 hips and legs
//    (knees), 1.2 up-legs (thighs), 0 for the rest; found by position in the
//    chains, so any skeleton with a body-region map works.
//  - One graph per part: consecutive frames, plus transitions i → j where
//    d_p(i, j) is a local minimum of the part's distance map and below the
//    part's share of the global threshold (shares proportional to the parts'
//    joint-weight sums); edge weight d (3.1). Parts with the lower chain
//    only connect frames of the same foot-contact phase. Transitions are
//    kept inside the largest strongly connected component (Tarjan).
//  - Search: Dijkstra in the lower (prior) part from the request frame to
//    any frame of the target clip; then in every other part from the lower
//    part's origin frame, leaving the source clip within the progressiveness
//    window after it and entering the target clip within the window after
//    the lower part's target frame (one candidate per target frame: its
//    cheapest path); combinations in which two non-prior parts' path lengths
//    differ by more than max_path_length_ratio (of the longer) are dropped;
//    the combination with the minimum total cost wins.
//  - Synchronisation by linear time scaling of each part's path, a
//    zero-phase Gaussian low-pass filter, and the root from the lower part's
//    velocities.
//
// Built objects are immutable and safe to read from many threads; searches
// use a caller-owned SearchWorkspace and allocate nothing once it is warm.
#pragma once

#include <numbers>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/motion/skeleton.h"
#include "common/status/cancel.h"
#include "common/status/status.h"
#include "services/planner/library/library.h"

namespace kinemo::planner::locomotion {

// An angle in radians wrapped to [-pi, pi].
inline double WrapAngle(double a) {
  while (a > std::numbers::pi) a -= 2 * std::numbers::pi;
  while (a < -std::numbers::pi) a += 2 * std::numbers::pi;
  return a;
}

enum class Chain : uint8_t { kHead, kTrunk, kUpperRight, kUpperLeft, kLower };
inline constexpr int kNumChains = 5;
// "head", "trunk", "upper_right", "upper_left", "lower".
std::string_view ChainName(Chain chain);

struct SplitProfile {
  std::string name;
  std::vector<std::vector<Chain>> parts;
};

// "SMG", "SP2", "SP3a", "SP3b", "SP4a", "SP4b", "SP5".
const std::vector<std::string>& BuiltinProfileNames();
// NOT_FOUND-free: INVALID_ARGUMENT "profile.name: ..." for unknown names.
//   SMG  {all}
//   SP2  {lower} {head trunk upper_right upper_left}
//   SP3a {lower} {head trunk upper_right} {upper_left}
//   SP3b {lower} {head} {trunk upper_right upper_left}
//   SP4a {lower} {head} {trunk} {upper_right upper_left}
//   SP4b {lower} {head trunk} {upper_right} {upper_left}
//   SP5  {lower} {head} {trunk} {upper_right} {upper_left}
// Fig. 3.13 is a picture; these are read from §3.5.1's discussion (SP4b and
// SP5 split the arms, SP4a and SP3b keep them together, SP4b keeps the head
// with the trunk, SP3a splits the upper body into two sides).
StatusOr<SplitProfile> BuiltinProfile(std::string_view name);
// Every chain in exactly one part; errors start with "profile".
Status ValidateProfile(const SplitProfile& profile);

struct GraphParams {
  double threshold = 0.105;
  std::map<std::string, double, std::less<>> joint_weights;  // overrides by joint name
  int progressive_window_frames = 0;  // 0 = 10 frames at 60 fps, scaled to the clips' rate
  double max_path_length_ratio = 0.2;
  double contact_height_m = 0.05;
  double contact_speed_mps = 0.8;
  double filter_cutoff_hz = 6;
  int max_transitions_per_frame = 0;  // 0 = unlimited; else the cheapest n per frame and part
};
// Fills zeros with defaults and checks ranges; errors name the field.
StatusOr<GraphParams> ResolveParams(GraphParams params);

// Limits.
inline constexpr int kMaxFrames = 8000;  // frames in all clips (distance maps are N²)

// A weighted joint of the distance metric.
struct WeightedJoint {
  int joint = -1;
  Chain chain = Chain::kTrunk;
  double weight = 0;
  bool hips = false;  // world rotation without heading
};

// Per-frame features of a library, shared by every graph built on it
// (profile and threshold independent).
struct LocomotionData {
  std::shared_ptr<const Library> library;
  int num_frames = 0;
  double fps = 0;
  double meters_per_unit = 0.01;
  std::vector<int> clip_begin;  // global index of each clip's first frame; size clips+1
  std::vector<int> clip_of;     // per global frame
  std::vector<Chain> joint_chain;  // per skeleton joint
  int hips = -1;
  std::vector<int> root_chain;  // hips and its ancestors, root first
  int left_foot = -1, right_foot = -1, left_upleg = -1, right_upleg = -1;
  int left_toe = -1, right_toe = -1;  // -1 if the skeleton has none
  std::vector<WeightedJoint> weighted;
  std::array<double, kNumChains> chain_weight{};  // sum of joint weights per chain
  // num_frames × weighted.size() rotations used by the distance.
  std::vector<Eigen::Quaterniond> quat;
  // Per chain, num_frames² distances (float, row-major).
  std::array<std::vector<float>, kNumChains> chain_distance;
  // Foot-contact phase per frame: bit 0 left, bit 1 right in contact.
  std::vector<uint8_t> phase;
  // Root motion per frame: hips world position (metres), heading (rad,
  // counter-clockwise from +x seen from above), and the velocity to the next
  // frame of the clip in the frame's heading frame (metres per frame, rad per frame).
  std::vector<Eigen::Vector3d> hips_position_m;
  std::vector<double> heading_rad;
  std::vector<Eigen::Vector2d> velocity_m;  // (forward, left)
  std::vector<double> turn_rad;
  std::vector<Eigen::Quaterniond> hips_rotation;  // world
  // Per global frame, its channel values (a view into the library clips).
  const double* FrameValues(int g) const;

  int ClipIndex(std::string_view name) const;
  int FrameInClip(int g) const { return g - clip_begin[static_cast<size_t>(clip_of[static_cast<size_t>(g)])]; }
  const Eigen::Quaterniond& Quat(int g, size_t k) const { return quat[static_cast<size_t>(g) * weighted.size() + k]; }
};

// Computes the features; `params` gives the joint weight overrides and the
// contact thresholds. Errors: fewer than 2 clips, missing key joints, more
// than kMaxFrames frames ("library: ...").
StatusOr<std::shared_ptr<const LocomotionData>> BuildLocomotionData(std::shared_ptr<const Library> library,
                                                                     const GraphParams& params);

// One body part's graph (CSR adjacency).
struct PartGraph {
  std::vector<Chain> chains;
  bool lower = false;
  double weight_sum = 0;
  double threshold = 0;
  std::vector<int> first_edge;  // num_frames + 1
  std::vector<int> edge_to;
  std::vector<float> edge_weight;
  std::vector<uint8_t> edge_transition;  // 0 = consecutive frames
  std::vector<uint8_t> in_scc;
  int scc_nodes = 0;
  int64_t scc_edges = 0;
  double Distance(const LocomotionData& d, int a, int b) const;
};

// A body part's candidate transitions before any threshold: the local
// minima of its distance map within each clip-pair block, away from a clip's
// own diagonal, in the same foot phase for the lower body (CSR by frame, in
// frame order). Threshold independent: found once per part and shared by the
// graphs of every threshold (Evaluate).
struct PartCandidates {
  std::vector<Chain> chains;  // in the order their distances are summed
  int num_frames = 0;
  std::vector<int> first;       // num_frames + 1
  std::vector<int> to;
  std::vector<double> distance;  // PartGraph::Distance
};
std::shared_ptr<const PartCandidates> FindPartCandidates(const LocomotionData& data, const std::vector<Chain>& chains);

class LocomotionGraph {
 public:
  // Builds every part's graph; parts are reordered so that the part with the
  // lower chain is first (the prior part). `shared` may hold the candidates
  // of some parts (same chains in the same order, same data); the others are
  // found here.
  static StatusOr<std::shared_ptr<const LocomotionGraph>> Build(
      std::shared_ptr<const LocomotionData> data, const SplitProfile& profile, const GraphParams& params,
      std::span<const std::shared_ptr<const PartCandidates>> shared = {});

  const LocomotionData& data() const { return *data_; }
  std::shared_ptr<const LocomotionData> data_ptr() const { return data_; }
  const SplitProfile& profile() const { return profile_; }
  const GraphParams& params() const { return params_; }
  const std::vector<PartGraph>& parts() const { return parts_; }
  int window_frames() const { return window_; }
  // Fraction of frames in every part's largest SCC.
  double connectivity() const { return connectivity_; }
  // Clips with frames in every part's largest SCC.
  int connected_clips() const { return connected_clips_; }
  double build_s() const { return build_s_; }

  int version = 1;  // set by the store

 private:
  LocomotionGraph() = default;
  std::shared_ptr<const LocomotionData> data_;
  SplitProfile profile_;
  GraphParams params_;
  std::vector<PartGraph> parts_;
  int window_ = 10;
  double connectivity_ = 0;
  int connected_clips_ = 0;
  double build_s_ = 0;
};

// A part's transition: plays the source clip up to `origin`, then `path`
// (global frames, origin first, target last) stretched over `duration`
// frames, then the target clip from `target`.
struct PartPath {
  int origin = -1;  // global frame
  int target = -1;  // global frame (in the target clip)
  std::vector<int> path;
  int length = 0;         // path.size() - 1
  double duration = 0;    // frames after synchronisation
  double start = 0;       // output frames after the request where the part leaves
  double cost = 0;        // Dijkstra cost
};

struct Transition {
  int request = -1;  // global frame
  int target_clip = -1;
  std::vector<PartPath> parts;  // same order as graph.parts()
  int total_frames = 0;       // TBF (3.3): output frames from request to all parts in the target clip
  int response_frames = 0;    // first part's start − request
  int end_frame = -1;         // global frame of the target clip reached by every part at total_frames
  double search_cost = 0;     // Σ part costs
};

// Reusable buffers for searches (one per thread).
class SearchWorkspace {
 public:
  void Reserve(int num_frames);
  std::vector<float> dist;
  std::vector<int> prev;
  std::vector<int> length;
  std::vector<uint8_t> on_run;
  std::vector<uint32_t> stamp;
  uint32_t current = 0;
  std::vector<std::pair<float, int>> heap;
  // Candidates of the non-prior parts (reused between searches).
  struct Candidate {
    int node = -1, origin = -1, length = 0;
    double cost = 0;
  };
  std::vector<std::vector<Candidate>> candidates;
  std::vector<std::vector<std::vector<int>>> candidate_paths;
};

// Plans a transition from global frame `request` to any frame of
// `target_clip`. NOT_FOUND ("to_clip: ...") when no transition exists.
Status PlanTransition(const LocomotionGraph& graph, int request, int target_clip, SearchWorkspace* ws,
                      Transition* out);

// PlanTransition in several graphs of the same data and parameters (split
// profiles differ), sharing the searches that are the same in several plans:
// the prior part's search between graphs with the same lower part (every
// built-in profile but SMG), and a part's candidates between plans whose
// prior part leaves and arrives at the same frames (the requests of a clip
// mostly leave at the same transitions). The same results as PlanTransition
// on each graph. One per thread; Reset() drops what it keeps (e.g. between
// clip pairs).
class SharedPlanner {
 public:
  explicit SharedPlanner(std::vector<std::shared_ptr<const LocomotionGraph>> graphs);
  Status Plan(size_t graph, int request, int target_clip, Transition* out);
  void Reset();

 private:
  struct PriorEntry {
    int request = -1, target_clip = -1;
    Status status;
    PartPath lower;
    double cost = 0;
  };
  // (part, prior origin, prior target, prior length, target clip)
  using CandidateKey = std::array<int, 5>;
  struct CandidateEntry {
    std::vector<SearchWorkspace::Candidate> cands;
    std::vector<std::vector<int>> paths;
  };
  std::vector<std::shared_ptr<const LocomotionGraph>> graphs_;
  std::vector<std::vector<Chain>> part_keys_;      // sorted chains of each distinct part
  std::vector<const PartGraph*> unique_parts_;     // a graph's part for each key
  std::vector<std::vector<int>> part_ids_;         // per graph, per part: index of its key
  std::vector<PriorEntry> priors_;                 // per distinct part: the last prior search
  std::map<CandidateKey, CandidateEntry> candidates_;
  SearchWorkspace ws_;
};

// Where each part is at output frame t (0 = request frame): global frames a,
// b and the blend alpha (b = a and alpha = 0 off the paths).
struct PartSample {
  int a = 0, b = 0;
  double alpha = 0;
};
void SamplePart(const LocomotionGraph& graph, const Transition& tr, size_t part, double t, PartSample* out);

// Full-body transition cost: Σ of full-body distances (all weighted joints)
// between consecutive output frames, from the request to total_frames.
double TransitionCost(const LocomotionGraph& graph, const Transition& tr);

// Root state on the surface for motion output.
struct RootState {
  Eigen::Vector2d position_m = Eigen::Vector2d::Zero();  // surface (x, y) = world (X, -Z)
  double heading_rad = 0;
};

// Full-body frames (library skeleton channels) of a transition, request to
// total_frames inclusive, low-pass filtered; the root starts at the request
// frame's own position and heading and follows the lower part's velocities.
StatusOr<motion::Clip> TransitionMotion(const LocomotionGraph& graph, const Transition& tr);

// Writes one full-body frame: each part's blended local rotations; the hips
// world transform placed at `root` (surface) with the lower part's height
// and heading-free orientation. `reference` (previous output frame or null)
// keeps Euler angles continuous. Allocation-free given a sized `out`.
void ComposeFrame(const LocomotionData& data, const std::vector<PartSample>& parts,
                  const std::vector<int>& part_of_chain, const RootState& root, const double* reference,
                  std::span<double> out);

// Zero-phase Gaussian low-pass filter (−3 dB at cutoff_hz) over the rotation
// channels of frames [0, n) in place.
void LowPass(const motion::Skeleton& skeleton, double fps, double cutoff_hz, motion::FrameMatrix* frames);

// Contacts of a clip's frames (bit 0 left, bit 1 right): a foot is in
// contact when its ankle or its toe joint is both low (height above that
// joint's lowest position in the clip) and slow.
std::vector<uint8_t> FootContacts(const LocomotionData& data, const motion::Clip& clip, double height_m,
                                  double speed_mps);

// ---- Evaluation (Tables 3.2-3.3, Figs. 3.14-3.15)

struct EvaluationOptions {
  std::vector<SplitProfile> profiles;  // empty = every built-in
  std::vector<double> thresholds;     // empty = 0.05 .. 0.50 step 0.025
  GraphParams params;
  int request_stride = 1;  // every n-th frame is a request frame
  bool maneuverability = false;
  int threads = 0;  // 0 = one per core; the rows do not depend on it
  // Checked between thresholds and between work items (null = never
  // stops): DEADLINE_EXCEEDED or CANCELLED ("evaluation: ...") once stopped.
  const CancelToken* cancel = nullptr;
};

struct EvaluationRow {
  std::string method;
  double threshold = 0;
  int connected_clips = 0;
  double tbf_frames = 0;       // mean over successful transitions
  double response_frames = 0;  // mean
  double connectivity = 0;
  double cost = 0;             // mean full-body transition cost
  double success_rate = 0;     // successful / requested (request, target) pairs
  int transitions = 0;
  std::vector<double> maneuverability;  // clips², LM (3.4) in frames (NaN = none)
  std::vector<double> response_matrix;  // clips², mean response per clip pair
  double build_s = 0;
  std::vector<double> search_us;      // per search, wall clock (for percentiles)
  std::vector<double> search_cpu_us;  // per search, this thread's CPU time (immune to preemption)
};

// Rows in profile-major order (every threshold of the first profile, then
// the next). Shares work between thresholds (each distinct part's candidate
// transitions are found once: FindPartCandidates) and between profiles and
// requests (SharedPlanner), on `threads` threads; each row's means are summed
// in request order, so the rows are the same as one PlanTransition per
// (profile, threshold, request, target) on one thread.
StatusOr<std::vector<EvaluationRow>> Evaluate(std::shared_ptr<const LocomotionData> data,
                                              const EvaluationOptions& options);

// ---- AvatAR driving (§5.2)

// The thesis' cube angle → 'Speed': 0 for 0-45°, else 0-180° mapped
// linearly to 1.55-5.55 (angles folded into [0, 180]).
double CubeAngleToSpeed(double angle_deg);

struct DriveParams {
  std::string idle_clip, walk_clip, run_clip;
  RootState start;
  double walk_min_speed = 0.5;
  double run_min_speed = 3.5;
  double arrival_radius_m = 0.05;
  double max_turn_deg_per_s = 180;
};

enum class DriveState : uint8_t { kIdle, kWalk, kRun, kTransition };

struct DriveStatus {
  double time_s = 0;
  RootState root;
  double speed_mps = 0;
  DriveState state = DriveState::kIdle;
  double distance_to_target_m = 0;
  bool target_reached = false;
};

// A transition the driver played (for checks): the lower part's path.
struct DriveTransitionRecord {
  int from_clip = -1, to_clip = -1;
  std::vector<int> lower_path;
  double start_s = 0;
};

// The AvatAR: a character on the surface that follows speed, target and
// path commands through BPMG transitions between idle, walk and run clips.
// Not thread-safe (one per stream).
class AvatarDriver {
 public:
  static StatusOr<std::unique_ptr<AvatarDriver>> Create(std::shared_ptr<const LocomotionGraph> graph,
                                                        DriveParams params);
  Status SetSpeed(double speed);  // 'Speed', [0, 5.55]
  void SetTarget(const Eigen::Vector2d& target_m);
  Status SetPath(std::vector<Eigen::Vector2d> points_m, bool loop);
  void Stop();

  // Produces the next frame into `out` (library skeleton channels).
  void Step(std::span<double> out);
  const DriveStatus& status() const { return status_; }
  double speed() const { return speed_; }
  const std::vector<DriveTransitionRecord>& transitions() const { return records_; }
  const LocomotionGraph& graph() const { return *graph_; }

 private:
  AvatarDriver() = default;
  int DesiredClip() const;
  bool HasGoal() const;
  Eigen::Vector2d Goal() const;
  double PredictStopTravel();
  void StartTransition(int clip);

  std::shared_ptr<const LocomotionGraph> graph_;
  DriveParams params_;
  int idle_ = -1, walk_ = -1, run_ = -1;
  std::vector<std::pair<int, int>> loop_;  // per clip: jump from .first to .second
  double speed_ = 0;
  bool has_target_ = false;
  Eigen::Vector2d target_ = Eigen::Vector2d::Zero();
  std::vector<Eigen::Vector2d> path_;
  bool path_loop_ = false;
  size_t path_index_ = 0;
  bool stopping_ = false;  // committed to idle for arrival
  bool arrived_ = false;   // at the final target; idle until it moves
  // Playback.
  int frame_ = 0;  // global frame when not in a transition
  bool in_transition_ = false;
  Transition transition_;
  int t_ = 0;
  int retry_wait_ = 0;
  SearchWorkspace ws_;
  std::vector<int> part_of_chain_;
  std::vector<PartSample> samples_;
  std::vector<double> previous_;
  bool has_previous_ = false;
  int64_t frames_out_ = 0;
  DriveStatus status_;
  std::vector<DriveTransitionRecord> records_;
};

}  // namespace kinemo::planner::locomotion
