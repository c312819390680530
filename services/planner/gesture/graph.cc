#include "services/planner/gesture/graph.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "common/motion/kinematics.h"
#include "services/planner/library/feet.h"

namespace kinemo::planner::gesture {
namespace {

bool ContainsWord(std::string name, const char* word) {
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return name.find(word) != std::string::npos;
}

Eigen::Quaterniond LocalQuat(const motion::Joint& joint, std::span<const double> frame) {
  return Eigen::Quaterniond(motion::LocalRotation(joint, frame)).normalized();
}

// Boundary poses of every phrase: start (first frame) and end (last frame).
struct Boundaries {
  std::vector<PoseMetric::Pose> start, end;
};

Boundaries ComputeBoundaries(const Library& library, const PhraseSet& set, const PoseMetric& metric) {
  Boundaries b;
  for (const auto& p : set.phrases) {
    const motion::Clip& clip = library.clips[static_cast<size_t>(p.clip)].clip;
    b.start.push_back(metric.At(clip, p.first_frame));
    b.end.push_back(metric.At(clip, p.end_frame - 1));
  }
  return b;
}

// E1: the next phrase of the same clip starts where this one ends.
bool Consecutive(const Phrase& a, const Phrase& b) {
  return a.clip == b.clip && b.first_frame >= a.end_frame - 1 && b.first_frame <= a.end_frame + 1;
}

}  // namespace

StatusOr<PoseMetric> PoseMetric::Create(const Library& library, double velocity_weight) {
  PoseMetric m;
  m.velocity_weight_ = velocity_weight;
  const auto& sk = library.skeleton;
  const auto& reg = library.regions;
  // Spine: trunk joints that are neither the root nor the hips/pelvis.
  for (int j : reg.JointsIn(motion::BodyRegion::kTrunk)) {
    const std::string& n = sk.joint(j).name;
    if (sk.joint(j).parent < 0 || ContainsWord(n, "root") || ContainsWord(n, "hip") || ContainsWord(n, "pelvis")) {
      continue;
    }
    if (sk.joint(j).num_rotations > 0) m.joints_.push_back(j);
  }
  // Neck: the topmost head-region joint when the region has more than one.
  std::vector<int> head = reg.JointsIn(motion::BodyRegion::kHead);
  if (head.size() >= 2) {
    m.joints_.push_back(*std::min_element(head.begin(), head.end(),
                                          [&](int a, int b) { return sk.depth(a) < sk.depth(b); }));
  }
  // Arms and forearms: the two lowest joints of each arm region.
  for (auto region : {motion::BodyRegion::kLeftArm, motion::BodyRegion::kRightArm}) {
    std::vector<int> js = reg.JointsIn(region);
    std::sort(js.begin(), js.end(), [&](int a, int b) { return sk.depth(a) < sk.depth(b); });
    if (js.size() < 2) return absl::FailedPreconditionError("library: the skeleton has no arm chains");
    m.joints_.push_back(js[js.size() - 2]);
    m.joints_.push_back(js[js.size() - 1]);
  }
  std::sort(m.joints_.begin(), m.joints_.end());
  m.joints_.erase(std::unique(m.joints_.begin(), m.joints_.end()), m.joints_.end());
  return m;
}

PoseMetric::Pose PoseMetric::At(const motion::Clip& clip, int f) const {
  Pose p;
  const int n = clip.num_frames();
  f = std::clamp(f, 0, n - 1);
  const int f0 = std::max(0, f - 1), f1 = std::min(n - 1, f + 1);
  const double span = std::max(1, f1 - f0) * clip.frame_time_s;
  for (int j : joints_) {
    const motion::Joint& joint = clip.skeleton.joint(j);
    p.q.push_back(LocalQuat(joint, clip.frame(f)));
    const Eigen::Quaterniond a = LocalQuat(joint, clip.frame(f0)), b = LocalQuat(joint, clip.frame(f1));
    const Eigen::AngleAxisd d(a.conjugate() * b);
    p.w.push_back(d.axis() * (d.angle() / span));
  }
  return p;
}

double PoseMetric::Distance(const Pose& a, const Pose& b) const {
  double d = 0;
  for (size_t k = 0; k < a.q.size(); ++k) {
    const double theta = a.q[k].angularDistance(b.q[k]);
    d += theta * theta + velocity_weight_ * (a.w[k] - b.w[k]).squaredNorm();
  }
  return d;
}

double PoseMetric::BlendLength(const Pose& a, const Pose& b, const GraphParams& p) const {
  double len = 0;
  for (size_t k = 0; k < a.q.size(); ++k) {
    const double theta = a.q[k].angularDistance(b.q[k]);
    const double w = std::max(0.5 * (a.w[k].norm() + b.w[k].norm()), p.min_angular_speed_rad_s);
    len = std::max(len, theta / w);
  }
  return std::clamp(len, p.blend_min_s, p.blend_max_s);
}

std::vector<int> StronglyConnectedComponents(const std::vector<std::vector<int>>& adj, int* largest) {
  const int n = static_cast<int>(adj.size());
  std::vector<int> index(static_cast<size_t>(n), -1), low(static_cast<size_t>(n), 0), comp(static_cast<size_t>(n), -1);
  std::vector<bool> on_stack(static_cast<size_t>(n), false);
  std::vector<int> stack;
  std::vector<std::pair<int, size_t>> call;  // node, next edge
  int counter = 0, ncomp = 0;
  std::vector<int> sizes;
  for (int root = 0; root < n; ++root) {
    if (index[static_cast<size_t>(root)] >= 0) continue;
    call.push_back({root, 0});
    while (!call.empty()) {
      auto& [v, e] = call.back();
      const size_t uv = static_cast<size_t>(v);
      if (e == 0 && index[uv] < 0) {
        index[uv] = low[uv] = counter++;
        stack.push_back(v);
        on_stack[uv] = true;
      }
      if (e < adj[uv].size()) {
        const int w = adj[uv][e++];
        const size_t uw = static_cast<size_t>(w);
        if (index[uw] < 0) {
          call.push_back({w, 0});
        } else if (on_stack[uw]) {
          low[uv] = std::min(low[uv], index[uw]);
        }
        continue;
      }
      if (low[uv] == index[uv]) {
        int size = 0;
        while (true) {
          const int w = stack.back();
          stack.pop_back();
          on_stack[static_cast<size_t>(w)] = false;
          comp[static_cast<size_t>(w)] = ncomp;
          ++size;
          if (w == v) break;
        }
        sizes.push_back(size);
        ++ncomp;
      }
      const int done = v;
      call.pop_back();
      if (!call.empty()) {
        const size_t up = static_cast<size_t>(call.back().first);
        low[up] = std::min(low[up], low[static_cast<size_t>(done)]);
      }
    }
  }
  if (largest) {
    *largest = sizes.empty() ? -1 : static_cast<int>(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
  }
  return comp;
}

namespace {

struct Adjacency {
  std::vector<std::vector<Edge>> out;
  int e1 = 0, e2 = 0;
};

Adjacency Connect(const PhraseSet& set, const std::vector<double>& dist, const GraphParams& p) {
  const int n = static_cast<int>(set.phrases.size());
  Adjacency a;
  a.out.resize(static_cast<size_t>(n));
  for (int m = 0; m < n; ++m) {
    for (int k = 0; k < n; ++k) {
      if (k == m) continue;
      if (Consecutive(set.phrases[static_cast<size_t>(m)], set.phrases[static_cast<size_t>(k)])) {
        a.out[static_cast<size_t>(m)].push_back({k, EdgeKind::kConsecutive, 0.0, 0.0});
        ++a.e1;
        continue;
      }
      const double d = dist[static_cast<size_t>(m) * static_cast<size_t>(n) + static_cast<size_t>(k)];
      if (d < p.similarity_threshold) {
        a.out[static_cast<size_t>(m)].push_back({k, EdgeKind::kSimilarity, d, 0.0});
        ++a.e2;
      }
    }
  }
  return a;
}

GraphStats StatsOf(const Adjacency& a, double st, std::vector<int>* comp_out, int* largest_out) {
  const int n = static_cast<int>(a.out.size());
  std::vector<std::vector<int>> adj(static_cast<size_t>(n));
  size_t edges = 0;
  for (int m = 0; m < n; ++m) {
    for (const auto& e : a.out[static_cast<size_t>(m)]) adj[static_cast<size_t>(m)].push_back(e.to);
    edges += a.out[static_cast<size_t>(m)].size();
  }
  int largest = -1;
  std::vector<int> comp = StronglyConnectedComponents(adj, &largest);
  GraphStats s;
  s.similarity_threshold = st;
  s.size = n;
  s.branching_factor = n > 0 ? static_cast<double>(edges) / n : 0;
  size_t scc_edges = 0;
  for (int m = 0; m < n; ++m) {
    if (comp[static_cast<size_t>(m)] != largest) continue;
    ++s.scc_size;
    for (int k : adj[static_cast<size_t>(m)]) scc_edges += comp[static_cast<size_t>(k)] == largest;
  }
  s.scc_branching_factor = s.scc_size > 0 ? static_cast<double>(scc_edges) / s.scc_size : 0;
  if (comp_out) *comp_out = std::move(comp);
  if (largest_out) *largest_out = largest;
  return s;
}

std::vector<double> DistanceMatrix(const Boundaries& b, const PoseMetric& metric) {
  const size_t n = b.start.size();
  std::vector<double> d(n * n);
  for (size_t m = 0; m < n; ++m) {
    for (size_t k = 0; k < n; ++k) d[m * n + k] = metric.Distance(b.end[m], b.start[k]);
  }
  return d;
}

Status CheckParams(const GraphParams& p) {
  if (!(p.similarity_threshold > 0) || !std::isfinite(p.similarity_threshold)) {
    return InvalidField("params.similarity_threshold", "must be > 0");
  }
  return absl::OkStatus();
}

}  // namespace

StatusOr<std::vector<GraphStats>> GestureGraph::Sweep(const Library& library, const PhraseSet& set,
                                                      const std::vector<double>& thresholds,
                                                      const GraphParams& params) {
  KINEMO_ASSIGN_OR_RETURN(PoseMetric metric, PoseMetric::Create(library, params.velocity_weight));
  const std::vector<double> dist = DistanceMatrix(ComputeBoundaries(library, set, metric), metric);
  std::vector<GraphStats> rows;
  for (size_t i = 0; i < thresholds.size(); ++i) {
    GraphParams p = params;
    p.similarity_threshold = thresholds[i];
    if (!(thresholds[i] > 0) || !std::isfinite(thresholds[i])) {
      return InvalidField(kinemo::StrCat("sweep_thresholds[", i, "]"), "must be > 0");
    }
    rows.push_back(StatsOf(Connect(set, dist, p), thresholds[i], nullptr, nullptr));
  }
  return rows;
}

StatusOr<std::shared_ptr<GestureGraph>> GestureGraph::Build(std::shared_ptr<const Library> library, PhraseSet set,
                                                            const GraphParams& params) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_RETURN_IF_ERROR(CheckParams(params));
  if (set.phrases.empty()) {
    return absl::FailedPreconditionError("library_id: the library has no gesture phrases");
  }
  KINEMO_ASSIGN_OR_RETURN(PoseMetric metric, PoseMetric::Create(*library, params.velocity_weight));
  if (params.stroke_phrases) {
    const size_t n0 = set.phrases.size();
    for (size_t i = 0; i < n0; ++i) {
      const Phrase& p = set.phrases[i];
      if (p.phases.size() < 2) continue;
      Phrase s = p;
      s.first_frame = p.stroke().first_frame;
      s.end_frame = p.stroke().end_frame;
      s.phases = {p.stroke()};
      if (s.frames() >= 3) set.phrases.push_back(std::move(s));
    }
  }
  auto g = std::shared_ptr<GestureGraph>(new GestureGraph());
  g->library_ = library;
  g->params_ = params;
  const Boundaries b = ComputeBoundaries(*library, set, metric);
  const std::vector<double> dist = DistanceMatrix(b, metric);
  Adjacency adj = Connect(set, dist, params);
  std::vector<int> comp;
  int largest = -1;
  g->stats_ = StatsOf(adj, params.similarity_threshold, &comp, &largest);
  g->e1_ = adj.e1;
  g->e2_ = adj.e2;
  const int n = static_cast<int>(set.phrases.size());
  g->kept_.assign(static_cast<size_t>(n), false);
  for (int m = 0; m < n; ++m) {
    g->kept_[static_cast<size_t>(m)] = params.keep_all_components || comp[static_cast<size_t>(m)] == largest;
  }
  g->out_.resize(static_cast<size_t>(n));
  for (int m = 0; m < n; ++m) {
    if (!g->kept_[static_cast<size_t>(m)]) continue;
    for (Edge e : adj.out[static_cast<size_t>(m)]) {
      if (!g->kept_[static_cast<size_t>(e.to)]) continue;
      if (e.kind == EdgeKind::kSimilarity) {
        e.blend_s = metric.BlendLength(b.end[static_cast<size_t>(m)], b.start[static_cast<size_t>(e.to)], params);
      }
      g->out_[static_cast<size_t>(m)].push_back(e);
    }
  }
  if (!params.no_rest_pose) {
    // Rest pose: in the named clip, or the medoid of first frames, the frame
    // with the hands lowest and stillest.
    int rest = -1;
    if (!params.rest_pose_clip.empty()) {
      for (size_t c = 0; c < library->clips.size(); ++c) {
        if (library->clips[c].name == params.rest_pose_clip) rest = static_cast<int>(c);
      }
      if (rest < 0) return InvalidField("params.rest_pose_clip", "no clip '", params.rest_pose_clip, "'");
    } else {
      std::vector<PoseMetric::Pose> first;
      for (const auto& c : library->clips) first.push_back(metric.At(c.clip, 0));
      double best = std::numeric_limits<double>::infinity();
      for (size_t i = 0; i < first.size(); ++i) {
        double sum = 0;
        for (size_t k = 0; k < first.size(); ++k) sum += metric.Distance(first[i], first[k]);
        if (sum < best) best = sum, rest = static_cast<int>(i);
      }
    }
    g->rest_clip_ = rest;
    g->rest_frame_ = FindRestFrame(*library, rest).frame;
    g->rest_node_ = n;
    g->kept_.push_back(true);
    g->out_.emplace_back();
    const PoseMetric::Pose rest_pose = metric.At(library->clips[static_cast<size_t>(rest)].clip, g->rest_frame_);
    for (int m = 0; m < n; ++m) {
      if (!g->kept_[static_cast<size_t>(m)]) continue;
      const auto& s = b.start[static_cast<size_t>(m)];
      const auto& e = b.end[static_cast<size_t>(m)];
      g->out_[static_cast<size_t>(n)].push_back(
          {m, EdgeKind::kRest, metric.Distance(rest_pose, s), metric.BlendLength(rest_pose, s, params)});
      g->out_[static_cast<size_t>(m)].push_back(
          {n, EdgeKind::kRest, metric.Distance(e, rest_pose), metric.BlendLength(e, rest_pose, params)});
    }
  }
  g->metric_ = metric;
  g->start_poses_ = b.start;
  for (const auto& ph : set.phrases) {
    // Early exit: where the stroke ends, when a hold or retraction follows.
    int exit = -1;
    if (ph.stroke().end_frame < ph.end_frame - 1) exit = ph.stroke().end_frame;
    g->exit_frames_.push_back(exit);
    g->exit_poses_.push_back(
        exit >= 0 ? metric.At(library->clips[static_cast<size_t>(ph.clip)].clip, exit) : PoseMetric::Pose{});
  }
  g->phrases_ = std::move(set);
  if (StatusOr<motion::UpperBodyJoints> upper = motion::FindUpperBodyJoints(library->skeleton, library->regions);
      upper.ok()) {
    const double mpu = LibraryMetersPerUnit(*library);
    for (const auto& c : library->clips) {
      g->fastest_upper_body_m_s_ = std::max(g->fastest_upper_body_m_s_, motion::MaxUpperBodySpeed(c.clip, *upper, mpu));
    }
    g->upper_body_ = std::move(*upper);
  }
  g->build_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return g;
}

}  // namespace kinemo::planner::gesture
