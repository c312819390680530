// Body part graphs (construction, largest SCC) and the transition search.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "services/planner/locomotion/locomotion.h"

namespace kinemo::planner::locomotion {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// Iterative Tarjan: component id per node; returns the largest component's id.
int LargestScc(int n, const std::vector<int>& first, const std::vector<int>& to, std::vector<int>* comp) {
  std::vector<int> index(static_cast<size_t>(n), -1), low(static_cast<size_t>(n), 0), stack, edge_pos(static_cast<size_t>(n), 0);
  std::vector<uint8_t> on_stack(static_cast<size_t>(n), 0);
  std::vector<int> call;
  comp->assign(static_cast<size_t>(n), -1);
  int next = 0, ncomp = 0, best = -1, best_size = 0;
  for (int root = 0; root < n; ++root) {
    if (index[static_cast<size_t>(root)] >= 0) continue;
    call.push_back(root);
    index[static_cast<size_t>(root)] = low[static_cast<size_t>(root)] = next++;
    stack.push_back(root);
    on_stack[static_cast<size_t>(root)] = 1;
    edge_pos[static_cast<size_t>(root)] = first[static_cast<size_t>(root)];
    while (!call.empty()) {
      const int v = call.back();
      const size_t vs = static_cast<size_t>(v);
      if (edge_pos[vs] < first[vs + 1]) {
        const int w = to[static_cast<size_t>(edge_pos[vs]++)];
        const size_t ws = static_cast<size_t>(w);
        if (index[ws] < 0) {
          index[ws] = low[ws] = next++;
          stack.push_back(w);
          on_stack[ws] = 1;
          edge_pos[ws] = first[ws];
          call.push_back(w);
        } else if (on_stack[ws]) {
          low[vs] = std::min(low[vs], index[ws]);
        }
        continue;
      }
      if (low[vs] == index[vs]) {
        int size = 0;
        int w;
        do {
          w = stack.back();
          stack.pop_back();
          on_stack[static_cast<size_t>(w)] = 0;
          (*comp)[static_cast<size_t>(w)] = ncomp;
          ++size;
        } while (w != v);
        if (size > best_size) {
          best_size = size;
          best = ncomp;
        }
        ++ncomp;
      }
      call.pop_back();
      if (!call.empty()) {
        const size_t u = static_cast<size_t>(call.back());
        low[u] = std::min(low[u], low[vs]);
      }
    }
  }
  return best;
}

bool HasLower(const std::vector<Chain>& chains) {
  return std::find(chains.begin(), chains.end(), Chain::kLower) != chains.end();
}

}  // namespace

double PartGraph::Distance(const LocomotionData& d, int a, int b) const {
  double sum = 0;
  const size_t n = static_cast<size_t>(d.num_frames);
  for (Chain c : chains) sum += d.chain_distance[static_cast<size_t>(c)][static_cast<size_t>(a) * n + static_cast<size_t>(b)];
  return sum;
}

std::shared_ptr<const PartCandidates> FindPartCandidates(const LocomotionData& data, const std::vector<Chain>& chains) {
  auto c = std::make_shared<PartCandidates>();
  c->chains = chains;
  const int n = data.num_frames;
  c->num_frames = n;
  const bool lower = HasLower(chains);
  // Rows a-1, a, a+1 of the part's distance map, summed over its chains in
  // their order (as PartGraph::Distance does).
  const size_t un = static_cast<size_t>(n);
  std::vector<double> rows(3 * un);
  auto fill_row = [&](int a) {
    double* row = &rows[static_cast<size_t>((a + 3) % 3) * un];
    if (a < 0 || a >= n) return;
    std::fill(row, row + un, 0.0);
    for (Chain ch : chains) {
      const float* cd = &data.chain_distance[static_cast<size_t>(ch)][static_cast<size_t>(a) * un];
      for (size_t b = 0; b < un; ++b) row[b] += cd[b];
    }
  };
  auto dist = [&](int a, int b) { return rows[static_cast<size_t>((a + 3) % 3) * un + static_cast<size_t>(b)]; };
  fill_row(0);
  c->first.assign(un + 1, 0);
  for (int a = 0; a < n; ++a) {
    fill_row(a + 1);
    c->first[static_cast<size_t>(a)] = static_cast<int>(c->to.size());
    const int ca = data.clip_of[static_cast<size_t>(a)];
    const int a0 = data.clip_begin[static_cast<size_t>(ca)], a1 = data.clip_begin[static_cast<size_t>(ca) + 1];
    for (int b = 0; b < n; ++b) {
      const int cb = data.clip_of[static_cast<size_t>(b)];
      if (ca == cb && std::abs(a - b) < 3) continue;
      if (lower && data.phase[static_cast<size_t>(a)] != data.phase[static_cast<size_t>(b)]) continue;
      const double d = dist(a, b);
      const int b0 = data.clip_begin[static_cast<size_t>(cb)], b1 = data.clip_begin[static_cast<size_t>(cb) + 1];
      bool minimum = true;
      for (int da = -1; da <= 1 && minimum; ++da) {
        for (int db = -1; db <= 1; ++db) {
          if (da == 0 && db == 0) continue;
          const int x = a + da, y = b + db;
          if (x < a0 || x >= a1 || y < b0 || y >= b1) continue;
          if (dist(x, y) < d) {
            minimum = false;
            break;
          }
        }
      }
      if (minimum) {
        c->to.push_back(b);
        c->distance.push_back(d);
      }
    }
  }
  c->first[static_cast<size_t>(n)] = static_cast<int>(c->to.size());
  return c;
}

StatusOr<std::shared_ptr<const LocomotionGraph>> LocomotionGraph::Build(
    std::shared_ptr<const LocomotionData> data, const SplitProfile& profile, const GraphParams& params_in,
    std::span<const std::shared_ptr<const PartCandidates>> shared) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_RETURN_IF_ERROR(ValidateProfile(profile));
  KINEMO_ASSIGN_OR_RETURN(GraphParams params, ResolveParams(params_in));
  auto g = std::shared_ptr<LocomotionGraph>(new LocomotionGraph());
  g->data_ = data;
  g->profile_ = profile;
  g->params_ = params;
  g->window_ = params.progressive_window_frames > 0
                   ? params.progressive_window_frames
                   : std::max(1, static_cast<int>(std::lround(10.0 * data->fps / 60.0)));
  const int n = data->num_frames;
  double total_weight = 0;
  for (double w : data->chain_weight) total_weight += w;
  if (total_weight <= 0) return InvalidField("params.joint_weights", "all joint weights are 0");
  // Lower part first.
  std::vector<std::vector<Chain>> parts = profile.parts;
  std::stable_partition(parts.begin(), parts.end(), HasLower);
  for (const auto& chains : parts) {
    PartGraph pg;
    pg.chains = chains;
    pg.lower = HasLower(chains);
    for (Chain c : chains) pg.weight_sum += data->chain_weight[static_cast<size_t>(c)];
    pg.threshold = params.threshold * pg.weight_sum / total_weight;
    // Candidate transitions below the part's threshold (found once per part
    // for every threshold: FindPartCandidates), the cheapest n per frame.
    std::shared_ptr<const PartCandidates> found;
    for (const auto& c : shared) {
      if (c && c->chains == chains && c->num_frames == n) found = c;
    }
    if (!found) found = FindPartCandidates(*data, chains);
    std::vector<std::vector<std::pair<int, float>>> out(static_cast<size_t>(n));
    auto dist = [&](int a, int b) { return pg.Distance(*data, a, b); };
    for (int a = 0; a < n; ++a) {
      auto& edges = out[static_cast<size_t>(a)];
      for (int e = found->first[static_cast<size_t>(a)]; e < found->first[static_cast<size_t>(a) + 1]; ++e) {
        const double d = found->distance[static_cast<size_t>(e)];
        if (d < pg.threshold) edges.push_back({found->to[static_cast<size_t>(e)], static_cast<float>(d)});
      }
      const size_t cap = static_cast<size_t>(params.max_transitions_per_frame);
      if (cap > 0 && edges.size() > cap) {
        std::nth_element(edges.begin(), edges.begin() + static_cast<std::ptrdiff_t>(cap), edges.end(),
                         [](const auto& x, const auto& y) { return x.second < y.second; });
        edges.resize(cap);
        std::sort(edges.begin(), edges.end());
      }
    }
    // CSR with consecutive edges first.
    auto build_csr = [&](const std::vector<uint8_t>* keep) {
      pg.first_edge.assign(static_cast<size_t>(n) + 1, 0);
      pg.edge_to.clear();
      pg.edge_weight.clear();
      pg.edge_transition.clear();
      for (int a = 0; a < n; ++a) {
        pg.first_edge[static_cast<size_t>(a)] = static_cast<int>(pg.edge_to.size());
        const int ca = data->clip_of[static_cast<size_t>(a)];
        if (a + 1 < data->clip_begin[static_cast<size_t>(ca) + 1]) {
          pg.edge_to.push_back(a + 1);
          pg.edge_weight.push_back(static_cast<float>(dist(a, a + 1)));
          pg.edge_transition.push_back(0);
        }
        for (const auto& [b, w] : out[static_cast<size_t>(a)]) {
          if (keep && (!(*keep)[static_cast<size_t>(a)] || !(*keep)[static_cast<size_t>(b)])) continue;
          pg.edge_to.push_back(b);
          pg.edge_weight.push_back(w);
          pg.edge_transition.push_back(1);
        }
      }
      pg.first_edge[static_cast<size_t>(n)] = static_cast<int>(pg.edge_to.size());
    };
    build_csr(nullptr);
    std::vector<int> comp;
    const int best = LargestScc(n, pg.first_edge, pg.edge_to, &comp);
    pg.in_scc.assign(static_cast<size_t>(n), 0);
    for (int a = 0; a < n; ++a) pg.in_scc[static_cast<size_t>(a)] = comp[static_cast<size_t>(a)] == best ? 1 : 0;
    build_csr(&pg.in_scc);
    pg.scc_nodes = 0;
    pg.scc_edges = 0;
    for (int a = 0; a < n; ++a) {
      if (!pg.in_scc[static_cast<size_t>(a)]) continue;
      ++pg.scc_nodes;
      for (int e = pg.first_edge[static_cast<size_t>(a)]; e < pg.first_edge[static_cast<size_t>(a) + 1]; ++e) {
        if (pg.in_scc[static_cast<size_t>(pg.edge_to[static_cast<size_t>(e)])]) ++pg.scc_edges;
      }
    }
    g->parts_.push_back(std::move(pg));
  }
  // Connectivity: frames in every part's SCC; clips with frames in every SCC.
  int connected = 0;
  for (int a = 0; a < n; ++a) {
    bool all = true;
    for (const auto& pg : g->parts_) all = all && pg.in_scc[static_cast<size_t>(a)];
    connected += all ? 1 : 0;
  }
  g->connectivity_ = n > 0 ? static_cast<double>(connected) / n : 0;
  for (size_t c = 0; c + 1 < data->clip_begin.size(); ++c) {
    bool all = true;
    for (const auto& pg : g->parts_) {
      bool any = false;
      for (int a = data->clip_begin[c]; a < data->clip_begin[c + 1] && !any; ++a) any = pg.in_scc[static_cast<size_t>(a)];
      all = all && any;
    }
    g->connected_clips_ += all ? 1 : 0;
  }
  g->build_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return std::shared_ptr<const LocomotionGraph>(std::move(g));
}

void SearchWorkspace::Reserve(int n) {
  if (static_cast<int>(dist.size()) >= n) return;
  dist.resize(static_cast<size_t>(n));
  prev.resize(static_cast<size_t>(n));
  length.resize(static_cast<size_t>(n));
  on_run.resize(static_cast<size_t>(n));
  stamp.assign(static_cast<size_t>(n), 0);
  current = 0;
  heap.reserve(static_cast<size_t>(n) * 4);
}

namespace {

// Dijkstra in `pg` from `source`; nodes of `target_clip` are terminals (not
// expanded). Nodes reached by consecutive frames from the source form the
// initial run; with `run_limit` >= 0 the run stops at that global frame.
// Settled terminals are reported to `on_terminal(node)`; the search stops when
// it returns false.
// Target-clip nodes in [window_lo, window_hi] are terminals; those before the
// window only follow their clip (a part may enter the target clip early and
// play it into the window); those after it are not expanded.
template <typename F>
void Dijkstra(const LocomotionData& d, const PartGraph& pg, int source, int target_clip, int window_lo, int window_hi,
              int run_limit, int max_length, SearchWorkspace* ws, F on_terminal) {
  ws->Reserve(d.num_frames);
  if (++ws->current == 0) {
    std::fill(ws->stamp.begin(), ws->stamp.end(), 0);
    ws->current = 1;
  }
  const uint32_t cur = ws->current;
  auto touch = [&](int v) {
    const size_t vs = static_cast<size_t>(v);
    if (ws->stamp[vs] != cur) {
      ws->stamp[vs] = cur;
      ws->dist[vs] = kInf;
      ws->prev[vs] = -1;
      ws->length[vs] = 0;
      ws->on_run[vs] = 0;
    }
  };
  auto& heap = ws->heap;
  heap.clear();
  touch(source);
  ws->dist[static_cast<size_t>(source)] = 0;
  ws->on_run[static_cast<size_t>(source)] = 1;
  heap.push_back({0.0f, source});
  auto cmp = [](const std::pair<float, int>& x, const std::pair<float, int>& y) { return x.first > y.first; };
  const int t0 = d.clip_begin[static_cast<size_t>(target_clip)], t1 = d.clip_begin[static_cast<size_t>(target_clip) + 1];
  // Each node is settled once (non-negative weights): once every terminal
  // is, nothing more can be reported.
  int terminals_left = std::max(0, std::min(window_hi, t1 - 1) - std::max(window_lo, t0) + 1);
  while (!heap.empty() && terminals_left > 0) {
    std::pop_heap(heap.begin(), heap.end(), cmp);
    const auto [du, u] = heap.back();
    heap.pop_back();
    const size_t us = static_cast<size_t>(u);
    if (du > ws->dist[us]) continue;
    const bool in_target = u >= t0 && u < t1;
    if (in_target) {
      if (u >= window_lo && u <= window_hi) {
        if (!on_terminal(u)) return;
        --terminals_left;
        continue;
      }
      if (u > window_hi) continue;
    }
    if (max_length >= 0 && ws->length[us] >= max_length) continue;
    for (int e = pg.first_edge[us]; e < pg.first_edge[us + 1]; ++e) {
      const int v = pg.edge_to[static_cast<size_t>(e)];
      const bool consecutive = !pg.edge_transition[static_cast<size_t>(e)];
      if (in_target && !consecutive) continue;
      if (consecutive && ws->on_run[us] && run_limit >= 0 && u >= run_limit) continue;
      touch(v);
      const float nd = du + pg.edge_weight[static_cast<size_t>(e)];
      const size_t vs = static_cast<size_t>(v);
      if (nd < ws->dist[vs]) {
        ws->dist[vs] = nd;
        ws->prev[vs] = u;
        ws->length[vs] = ws->length[us] + 1;
        ws->on_run[vs] = consecutive && ws->on_run[us] ? 1 : 0;
        heap.push_back({nd, v});
        std::push_heap(heap.begin(), heap.end(), cmp);
      }
    }
  }
}

// The path source → node (from ws->prev), and its origin (last node of the
// initial run).
void ExtractPath(const SearchWorkspace& ws, int node, std::vector<int>* path, int* origin) {
  path->clear();
  for (int v = node; v >= 0; v = ws.prev[static_cast<size_t>(v)]) path->push_back(v);
  std::reverse(path->begin(), path->end());
  *origin = path->front();
  for (int v : *path) {
    if (ws.on_run[static_cast<size_t>(v)]) *origin = v;
  }
}

}  // namespace

namespace {

Status NoTransition(const LocomotionData& d, int request, int source_clip, int target_clip) {
  return absl::NotFoundError(kinemo::StrCat("to_clip: no transition from frame ", d.FrameInClip(request), " of '",
                                            d.library->clips[static_cast<size_t>(source_clip)].name, "' to '",
                                            d.library->clips[static_cast<size_t>(target_clip)].name, "'"));
}

// The prior (lower) part: from the request frame to the cheapest frame of
// the target clip. `lower` receives its path from the origin (the last frame
// of the source clip's run) and `prior_cost` the cost from the request.
Status SearchPrior(const LocomotionData& d, const PartGraph& pg, int request, int target_clip, SearchWorkspace* ws,
                   PartPath* lower, double* prior_cost) {
  int found = -1;
  Dijkstra(d, pg, request, target_clip, d.clip_begin[static_cast<size_t>(target_clip)],
           d.clip_begin[static_cast<size_t>(target_clip) + 1] - 1, -1, -1, ws, [&](int node) {
    found = node;
    return false;
  });
  if (found < 0) return NoTransition(d, request, d.clip_of[static_cast<size_t>(request)], target_clip);
  ExtractPath(*ws, found, &lower->path, &lower->origin);
  lower->path.erase(lower->path.begin(), std::find(lower->path.begin(), lower->path.end(), lower->origin));
  lower->target = found;
  lower->length = static_cast<int>(lower->path.size()) - 1;
  lower->duration = lower->length;
  lower->start = lower->origin - request;
  lower->cost = ws->dist[static_cast<size_t>(found)] - (ws->dist[static_cast<size_t>(lower->origin)]);
  *prior_cost = ws->dist[static_cast<size_t>(found)];
  return absl::OkStatus();
}

// Where a non-prior part may leave and arrive, given the prior part's path:
// leave within [origin, origin + w] of the source clip's run, arrive within
// [target, target + w]; paths far longer than the transition are not expanded.
struct PartWindow {
  int run_limit = 0, win_end = 0, max_length = 0;
};

PartWindow WindowOf(const LocomotionData& d, const PartPath& lower, int target_clip, int w) {
  const int source_end = d.clip_begin[static_cast<size_t>(d.clip_of[static_cast<size_t>(lower.origin)]) + 1];
  const int t_end = d.clip_begin[static_cast<size_t>(target_clip) + 1];
  return {std::min(lower.origin + w, source_end - 1), std::min(lower.target + w, t_end - 1),
          w + 4 * (lower.length + w)};
}

// A non-prior part's candidates: for each target frame in the window its
// cheapest path from the prior part's origin (one with at least one step and
// a positive duration).
void SearchCandidates(const LocomotionData& d, const PartGraph& pg, const PartPath& lower, int target_clip, int w,
                      SearchWorkspace* ws, std::vector<SearchWorkspace::Candidate>* cands,
                      std::vector<std::vector<int>>* paths) {
  const PartWindow win = WindowOf(d, lower, target_clip, w);
  cands->clear();
  Dijkstra(d, pg, lower.origin, target_clip, lower.target, win.win_end, win.run_limit, win.max_length, ws,
           [&](int node) {
    SearchWorkspace::Candidate c;
    c.node = node;
    if (paths->size() <= cands->size()) paths->emplace_back();
    std::vector<int>& path = (*paths)[cands->size()];
    ExtractPath(*ws, node, &path, &c.origin);
    c.length = ws->length[static_cast<size_t>(node)] - ws->length[static_cast<size_t>(c.origin)];
    c.cost = ws->dist[static_cast<size_t>(node)];
    const double duration = (lower.origin - c.origin) + lower.length + (node - lower.target);
    if (c.length >= 1 && duration >= 1) cands->push_back(c);
    return true;
  });
}

Status NoPartTransition(const LocomotionData& d, int request, size_t part) {
  const int source_clip = d.clip_of[static_cast<size_t>(request)];
  return absl::NotFoundError(kinemo::StrCat("to_clip: no transition for body part ", part,
                                            " within the window from frame ", d.FrameInClip(request), " of '",
                                            d.library->clips[static_cast<size_t>(source_clip)].name, "'"));
}

// The cheapest combination whose non-prior lengths are within `ratio` of
// each other: for each candidate length m as the shortest, every part takes
// its cheapest candidate with length in [m, m / (1 - ratio)]. cands[p] and
// paths[p] for parts p >= 1 (non-empty).
using CandidateLists = std::array<const std::vector<SearchWorkspace::Candidate>*, kNumChains>;
using CandidatePaths = std::array<const std::vector<std::vector<int>>*, kNumChains>;

Status Combine(const LocomotionGraph& graph, int request, const PartPath& lower, double prior_cost,
               const CandidateLists& cands, const CandidatePaths& paths, Transition* out) {
  const LocomotionData& d = graph.data();
  const size_t np = graph.parts().size();
  const double ratio = graph.params().max_path_length_ratio;
  double best_total = std::numeric_limits<double>::infinity();
  int best_m = -1;
  for (size_t q = 1; q < np; ++q) {
    for (const auto& cm : *cands[q]) {
      const int m = cm.length;
      const double hi = ratio < 1 ? m / (1 - ratio) + 1e-9 : std::numeric_limits<double>::infinity();
      double total = 0;
      bool all = true;
      for (size_t p = 1; p < np && all; ++p) {
        double best = std::numeric_limits<double>::infinity();
        for (const auto& c : *cands[p]) {
          if (c.length >= m && c.length <= hi) best = std::min(best, c.cost);
        }
        all = std::isfinite(best);
        total += best;
      }
      if (all && total < best_total) {
        best_total = total;
        best_m = m;
      }
    }
  }
  if (np > 1 && best_m < 0) {
    const int source_clip = d.clip_of[static_cast<size_t>(request)];
    return absl::NotFoundError(kinemo::StrCat("to_clip: no body part combination within the length ratio from frame ",
                                              d.FrameInClip(request), " of '",
                                              d.library->clips[static_cast<size_t>(source_clip)].name, "'"));
  }
  out->parts.resize(np);
  if (&out->parts[0] != &lower) out->parts[0] = lower;
  double search_cost = prior_cost;
  int max_target = lower.target;
  for (size_t p = 1; p < np; ++p) {
    const double hi = ratio < 1 ? best_m / (1 - ratio) + 1e-9 : std::numeric_limits<double>::infinity();
    size_t pick = 0;
    double best = std::numeric_limits<double>::infinity();
    const auto& cs = *cands[p];
    for (size_t k = 0; k < cs.size(); ++k) {
      if (cs[k].length >= best_m && cs[k].length <= hi && cs[k].cost < best) {
        best = cs[k].cost;
        pick = k;
      }
    }
    const auto& c = cs[pick];
    PartPath& pp = out->parts[p];
    const std::vector<int>& path = (*paths[p])[pick];
    pp.path.assign(std::find(path.begin(), path.end(), c.origin), path.end());
    pp.origin = c.origin;
    pp.target = c.node;
    pp.length = c.length;
    pp.duration = (lower.origin - c.origin) + lower.length + (c.node - lower.target);
    pp.start = c.origin - request;
    pp.cost = c.cost;
    search_cost += c.cost;
    max_target = std::max(max_target, c.node);
  }
  out->end_frame = max_target;
  out->total_frames = (lower.origin - request) + lower.length + (max_target - lower.target);
  double first = lower.start;
  for (const auto& pp : out->parts) first = std::min(first, pp.start);
  out->response_frames = static_cast<int>(first);
  out->search_cost = search_cost;
  return absl::OkStatus();
}

Status CheckRequest(const LocomotionData& d, int request, int target_clip) {
  if (request < 0 || request >= d.num_frames) return InvalidField("from_frame", "out of range");
  if (target_clip < 0 || target_clip + 1 >= static_cast<int>(d.clip_begin.size())) {
    return InvalidField("to_clip", "out of range");
  }
  if (d.clip_of[static_cast<size_t>(request)] == target_clip) {
    return InvalidField("to_clip", "is the clip already playing");
  }
  return absl::OkStatus();
}

}  // namespace

Status PlanTransition(const LocomotionGraph& graph, int request, int target_clip, SearchWorkspace* ws,
                      Transition* out) {
  const LocomotionData& d = graph.data();
  KINEMO_RETURN_IF_ERROR(CheckRequest(d, request, target_clip));
  out->request = request;
  out->target_clip = target_clip;
  const size_t np = graph.parts().size();
  out->parts.resize(np);
  PartPath& lower = out->parts[0];
  double prior_cost = 0;
  KINEMO_RETURN_IF_ERROR(SearchPrior(d, graph.parts()[0], request, target_clip, ws, &lower, &prior_cost));
  if (ws->candidates.size() < np) {
    ws->candidates.resize(np);
    ws->candidate_paths.resize(np);
  }
  CandidateLists cands{};
  CandidatePaths paths{};
  for (size_t p = 1; p < np; ++p) {
    SearchCandidates(d, graph.parts()[p], lower, target_clip, graph.window_frames(), ws, &ws->candidates[p],
                     &ws->candidate_paths[p]);
    if (ws->candidates[p].empty()) return NoPartTransition(d, request, p);
    cands[p] = &ws->candidates[p];
    paths[p] = &ws->candidate_paths[p];
  }
  return Combine(graph, request, lower, prior_cost, cands, paths, out);
}

SharedPlanner::SharedPlanner(std::vector<std::shared_ptr<const LocomotionGraph>> graphs) : graphs_(std::move(graphs)) {
  for (const auto& g : graphs_) {
    std::vector<int> ids;
    for (const PartGraph& pg : g->parts()) {
      // Chains in the same order: the part's distances are summed in it.
      const std::vector<Chain>& key = pg.chains;
      auto it = std::find(part_keys_.begin(), part_keys_.end(), key);
      if (it == part_keys_.end()) {
        part_keys_.push_back(key);
        unique_parts_.push_back(&pg);
        it = part_keys_.end() - 1;
      }
      ids.push_back(static_cast<int>(it - part_keys_.begin()));
    }
    part_ids_.push_back(std::move(ids));
  }
  priors_.resize(unique_parts_.size());
}

void SharedPlanner::Reset() {
  for (PriorEntry& e : priors_) e.request = -1;
  candidates_.clear();
}

Status SharedPlanner::Plan(size_t g, int request, int target_clip, Transition* out) {
  const LocomotionGraph& graph = *graphs_[g];
  const LocomotionData& d = graph.data();
  KINEMO_RETURN_IF_ERROR(CheckRequest(d, request, target_clip));
  out->request = request;
  out->target_clip = target_clip;
  const std::vector<int>& ids = part_ids_[g];
  PriorEntry& prior = priors_[static_cast<size_t>(ids[0])];
  if (prior.request != request || prior.target_clip != target_clip) {
    prior.request = request;
    prior.target_clip = target_clip;
    prior.status = SearchPrior(d, *unique_parts_[static_cast<size_t>(ids[0])], request, target_clip, &ws_,
                               &prior.lower, &prior.cost);
  }
  KINEMO_RETURN_IF_ERROR(prior.status);
  const PartPath& lower = prior.lower;
  const size_t np = graph.parts().size();
  CandidateLists cands{};
  CandidatePaths paths{};
  for (size_t p = 1; p < np; ++p) {
    // A part's candidates depend on the part and on where the prior part
    // leaves (origin) and arrives (target, length): WindowOf.
    const CandidateKey key{ids[p], lower.origin, lower.target, lower.length, target_clip};
    auto it = candidates_.find(key);
    if (it == candidates_.end()) {
      CandidateEntry e;
      SearchCandidates(d, *unique_parts_[static_cast<size_t>(ids[p])], lower, target_clip, graph.window_frames(),
                       &ws_, &e.cands, &e.paths);
      it = candidates_.emplace(key, std::move(e)).first;
    }
    if (it->second.cands.empty()) return NoPartTransition(d, request, p);
    cands[p] = &it->second.cands;
    paths[p] = &it->second.paths;
  }
  return Combine(graph, request, lower, prior.cost, cands, paths, out);
}

void SamplePart(const LocomotionGraph& graph, const Transition& tr, size_t part, double t, PartSample* out) {
  (void)graph;
  const PartPath& pp = tr.parts[part];
  const double leave = pp.start;
  const double arrive = pp.start + pp.duration;
  if (t <= leave) {
    const int f = tr.request + static_cast<int>(std::floor(t));
    const double frac = t - std::floor(t);
    out->a = f;
    out->b = frac > 0 && f < pp.origin ? f + 1 : f;
    out->alpha = out->b == f ? 0 : frac;
  } else if (t < arrive) {
    const double s = (t - leave) * pp.length / pp.duration;
    const int k = std::min(static_cast<int>(std::floor(s)), pp.length - 1);
    out->a = pp.path[static_cast<size_t>(k)];
    out->b = pp.path[static_cast<size_t>(k) + 1];
    out->alpha = s - k;
  } else {
    const double u = t - arrive;
    const int f = pp.target + static_cast<int>(std::floor(u));
    const double frac = u - std::floor(u);
    out->a = f;
    out->b = frac > 0 && f < tr.end_frame ? f + 1 : f;
    out->alpha = out->b == f ? 0 : frac;
  }
}

double TransitionCost(const LocomotionGraph& graph, const Transition& tr) {
  const LocomotionData& d = graph.data();
  const size_t nw = d.weighted.size();
  // Part of each weighted joint.
  std::array<size_t, kNumChains> part_of{};
  for (size_t p = 0; p < graph.parts().size(); ++p) {
    for (Chain c : graph.parts()[p].chains) part_of[static_cast<size_t>(c)] = p;
  }
  std::array<PartSample, 8> now{}, before{};
  const size_t np = std::min<size_t>(graph.parts().size(), 8);
  double cost = 0;
  for (int t = 0; t <= tr.total_frames; ++t) {
    for (size_t p = 0; p < np; ++p) SamplePart(graph, tr, p, t, &now[p]);
    if (t > 0) {
      for (size_t k = 0; k < nw; ++k) {
        const size_t p = part_of[static_cast<size_t>(d.weighted[k].chain)];
        const PartSample& x = now[p];
        const PartSample& y = before[p];
        const Eigen::Quaterniond qa = d.Quat(x.a, k).slerp(x.alpha, d.Quat(x.b, k));
        const Eigen::Quaterniond qb = d.Quat(y.a, k).slerp(y.alpha, d.Quat(y.b, k));
        const double th = std::acos(std::min(1.0, std::abs(qa.dot(qb))));
        cost += d.weighted[k].weight * th * th;
      }
    }
    before = now;
  }
  return cost;
}

}  // namespace kinemo::planner::locomotion
