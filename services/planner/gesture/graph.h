// Gesture Motion Graph (thesis §4.4.4, §4.5.1): nodes are gesture phrases;
// E1 edges join phrases that follow each other without a gap in a recording
// (weight 0); E2 edges join phrase m to n when the joint-angle distance
// d(m_ω, n_α) between m's last and n's first frame is below the similarity
// threshold st (weight d). The largest strongly connected component (Tarjan)
// is kept. A rest-pose node (BodySpeech) connects to and from every kept
// phrase (kind REST, weight = distance, no threshold: the motion always
// starts and ends at rest).
//
// Pose distance (Lee et al. 2002, joint-angle form, root position ignored):
//   d(a, b) = Σ_k w_k θ_k(a, b)² + ν Σ_k w_k |ω_k(a) − ω_k(b)|²
// θ_k = geodesic angle (radians) between the joint's local rotations, ω_k its
// angular velocity (rad/s, central difference), ν = `velocity_weight` (s²).
// Weights: spine joints (trunk region below the hips), the neck (first joint
// of the head region), upper arms and forearms 1; every other joint 0.
//
// Blend length per edge (BodySpeech's optimal blend length after Wang and
// Bodenheimer 2008: the transition lasts as long as the joints need to cover
// the gap at the speed they are moving):
//   L = clamp(max_k θ_k / max(ω̄_k, ω_min), blend_min_s, blend_max_s)
// with ω̄_k the mean angular speed of joint k at both ends; E1 edges need no
// blend (L = 0).
//
// A GestureGraph is immutable after Build and safe to read from many threads.
#pragma once

#include <Eigen/Geometry>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/motion/speed_limit.h"
#include "common/status/status.h"
#include "services/planner/gesture/phrases.h"
#include "services/planner/library/library.h"

namespace kinemo::planner::gesture {

enum class EdgeKind { kConsecutive, kSimilarity, kRest };

struct Edge {
  int to = 0;
  EdgeKind kind = EdgeKind::kSimilarity;
  double weight = 0;   // 0 for E1, the pose distance otherwise
  double blend_s = 0;  // optimal blend length (0 for E1)
};

struct GraphParams {
  double similarity_threshold = 1.0;
  bool keep_all_components = false;
  bool no_rest_pose = false;
  // The clip holding the rest pose; empty = the medoid of the clips' first
  // frames. The pose is that clip's frame with the hands lowest and stillest
  // (FindRestFrame), so a take that opens mid-gesture still rests with both
  // hands down.
  std::string rest_pose_clip;
  // BodySpeech §4.5.1: also add every stroke as a phrase of its own (for
  // phrases with other phases), after the library's phrases.
  bool stroke_phrases = false;
  double velocity_weight = 0.01;  // ν, s²
  double blend_min_s = 0.1;
  double blend_max_s = 0.5;
  double min_angular_speed_rad_s = 1.0;  // ω_min
};

// A row of Table 4.2.
struct GraphStats {
  double similarity_threshold = 0;
  int size = 0;                // nodes (phrases)
  double branching_factor = 0;  // edges / nodes
  int scc_size = 0;             // nodes of the largest SCC
  double scc_branching_factor = 0;
};

// Weighted joints and the per-phrase boundary poses the distances use.
class PoseMetric {
 public:
  static StatusOr<PoseMetric> Create(const Library& library, double velocity_weight);
  // Boundary features of frame f of a clip: rotations and angular velocities.
  struct Pose {
    std::vector<Eigen::Quaterniond> q;  // per weighted joint
    std::vector<Eigen::Vector3d> w;     // angular velocity, rad/s, per weighted joint
  };
  Pose At(const motion::Clip& clip, int f) const;
  double Distance(const Pose& a, const Pose& b) const;
  // Optimal blend length between two poses.
  double BlendLength(const Pose& a, const Pose& b, const GraphParams& p) const;
  const std::vector<int>& joints() const { return joints_; }

 private:
  std::vector<int> joints_;  // weight 1; all others 0
  double velocity_weight_ = 0;
};

class GestureGraph {
 public:
  static StatusOr<std::shared_ptr<GestureGraph>> Build(std::shared_ptr<const Library> library, PhraseSet phrases,
                                                       const GraphParams& params);

  // Table 4.2 statistics at each threshold (no graph stored).
  static StatusOr<std::vector<GraphStats>> Sweep(const Library& library, const PhraseSet& phrases,
                                                 const std::vector<double>& thresholds, const GraphParams& params);

  int version = 1;  // set by VersionedStore
  std::string id;

  const Library& library() const { return *library_; }
  std::shared_ptr<const Library> library_ptr() const { return library_; }
  const PhraseSet& phrase_set() const { return phrases_; }
  const std::vector<Phrase>& phrases() const { return phrases_.phrases; }
  const GraphParams& params() const { return params_; }
  const GraphStats& stats() const { return stats_; }
  int num_phrases() const { return static_cast<int>(phrases_.phrases.size()); }
  // Rest node id (== num_phrases()) or -1.
  int rest_node() const { return rest_node_; }
  int rest_clip() const { return rest_clip_; }
  int rest_frame() const { return rest_frame_; }
  bool kept(int node) const { return kept_[static_cast<size_t>(node)]; }
  // Out-edges of a node inside the kept component (and to/from rest).
  const std::vector<Edge>& out(int node) const { return out_[static_cast<size_t>(node)]; }
  int consecutive_edges() const { return e1_; }
  int similarity_edges() const { return e2_; }
  double build_s() const { return build_s_; }
  // Pose features for distances computed during synthesis.
  const PoseMetric& metric() const { return metric_; }
  const PoseMetric::Pose& start_pose(int node) const { return start_poses_[static_cast<size_t>(node)]; }
  // Early exit of a phrase: the frame where its stroke ends when a hold or
  // retraction follows (-1 otherwise), and the pose there.
  int exit_frame(int node) const { return exit_frames_[static_cast<size_t>(node)]; }
  const PoseMetric::Pose& exit_pose(int node) const { return exit_poses_[static_cast<size_t>(node)]; }
  // The head, elbows and wrists whose speed synthesis keeps under the
  // library's fastest (null when the skeleton has no head or hands), and that
  // fastest speed over every clip, m/s (measured once, at Build).
  const motion::UpperBodyJoints* upper_body() const { return upper_body_ ? &*upper_body_ : nullptr; }
  double fastest_upper_body_m_s() const { return fastest_upper_body_m_s_; }

 private:
  std::shared_ptr<const Library> library_;
  PhraseSet phrases_;
  GraphParams params_;
  GraphStats stats_;
  int rest_node_ = -1;
  int rest_clip_ = -1;
  int rest_frame_ = 0;
  std::vector<bool> kept_;
  std::vector<std::vector<Edge>> out_;
  PoseMetric metric_;
  std::vector<PoseMetric::Pose> start_poses_, exit_poses_;
  std::vector<int> exit_frames_;
  int e1_ = 0, e2_ = 0;
  double build_s_ = 0;
  std::optional<motion::UpperBodyJoints> upper_body_;
  double fastest_upper_body_m_s_ = 0;
};

using GestureGraphStore = VersionedStore<GestureGraph>;

// Tarjan's strongly connected components (iterative). Returns the component
// id of every node; `largest` gets the id of the biggest component.
std::vector<int> StronglyConnectedComponents(const std::vector<std::vector<int>>& adjacency, int* largest);

}  // namespace kinemo::planner::gesture
