// Offline synthesis with the Gesture Controller (Gesture Controllers §7.1
// "Offline Animation with Dynamic Programming": Q_t(a_j, f_j) = γ_t·δ_{a_j} +
// min [S + Q_{t−1}] over smoothed beliefs γ_t, keyword deadlines of §8.1), the
// online run over a belief sequence (§7.2's policy, for tests and the bench),
// the random-segments baseline, and style vectors from tone weights (§8.2).
// The offline build is in controller_build.cc, the policy and frame assembly
// in controller_runtime.cc.
#include "services/planner/controller/controller.h"

#include <algorithm>
#include <chrono>
#include <functional>
#include <cmath>
#include <random>

#include "services/planner/controller/controller_internal.h"

namespace kinemo::planner::controller {

using internal::kInf;
using internal::Seconds;

// ---------------------------------------------------------------------------
// Offline synthesis and online runs

namespace {

Status ValidateBeliefs(const Controller& c, const std::vector<BeliefSpan>& beliefs) {
  if (beliefs.empty()) return InvalidField("beliefs", "empty");
  for (size_t t = 0; t < beliefs.size(); ++t) {
    const auto& b = beliefs[t];
    const std::string f = kinemo::StrCat("beliefs[", t, "]");
    if (static_cast<int>(b.probabilities.size()) != c.num_states())
      return InvalidField(f, "has ", b.probabilities.size(), " probabilities, the controller has ", c.num_states(), " states");
    double sum = 0;
    for (double v : b.probabilities) {
      if (!std::isfinite(v) || v < 0) return InvalidField(f, "probabilities must be finite and non-negative");
      sum += v;
    }
    if (std::abs(sum - 1) > 1e-6) return InvalidField(f, "probabilities sum to ", sum, ", not 1");
    if (!std::isfinite(b.start_s) || !std::isfinite(b.end_s) || b.end_s < b.start_s || b.start_s < 0)
      return InvalidField(f, "times must be finite with 0 <= start_s <= end_s");
    if (t > 0 && b.start_s < beliefs[t - 1].start_s) return InvalidField(f, "times out of order");
  }
  return absl::OkStatus();
}

struct Prepared {
  int frames = 0;
  std::vector<double> style;
  std::vector<std::pair<int, KeywordEvent>> keywords;  // (keyword index, event), sorted by end
  int blend = 0;
};

StatusOr<Prepared> Prepare(const Controller& c, const std::vector<BeliefSpan>& beliefs, const SynthesisOptions& o) {
  KINEMO_RETURN_IF_ERROR(ValidateBeliefs(c, beliefs));
  if (o.feet.enabled) KINEMO_RETURN_IF_ERROR(motion::ValidateFootPlantParams(o.feet));
  if (!(o.start_s >= 0 && o.start_s <= 10)) return InvalidField("start_s", o.start_s, " is outside [0, 10] s");
  if (!(o.end_s >= 0 && o.end_s <= 10)) return InvalidField("end_s", o.end_s, " is outside [0, 10] s");
  if (!(o.max_run_s >= 0 && o.max_run_s <= 60)) return InvalidField("max_run_s", o.max_run_s, " is outside [0, 60] s");
  if (!(o.recent_s >= 0 && o.recent_s <= 60)) return InvalidField("recent_s", o.recent_s, " is outside [0, 60] s");
  Prepared p;
  const double duration = o.duration_s > 0 ? o.duration_s : beliefs.back().end_s;
  if (!std::isfinite(duration) || duration <= 0) return InvalidField("duration_s", "must be > 0");
  if (duration > o.max_duration_s) return InvalidField("duration_s", duration, " exceeds the limit of ", o.max_duration_s, " s");
  const double dt = c.frame_time_s();
  // BVH frame times are rounded (0.0333333): a few ppm over an integer is that integer.
  p.frames = std::max(1, static_cast<int>(std::ceil(duration / dt * (1 - 1e-5))));
  if (o.style.empty()) {
    p.style.assign(static_cast<size_t>(c.num_tones()), 0.0);
    const int n = c.ToneIndex(c.params().neutral_tone);
    p.style[static_cast<size_t>(n >= 0 ? n : 0)] = 1;
  } else {
    if (static_cast<int>(o.style.size()) != c.num_tones()) return InvalidField("style", "needs one weight per tone");
    double sum = 0;
    for (double v : o.style) {
      if (!std::isfinite(v) || v < 0) return InvalidField("style", "weights must be finite and non-negative");
      sum += v;
    }
    if (!(sum > 0)) return InvalidField("style", "weights sum to 0");
    for (double v : o.style) p.style.push_back(v / sum);
  }
  for (size_t k = 0; k < o.keywords.size(); ++k) {
    const auto& kw = o.keywords[k];
    if (!std::isfinite(kw.start_s) || !std::isfinite(kw.end_s) || kw.end_s < kw.start_s)
      return InvalidField(kinemo::StrCat("keywords[", k, "]"), "times must be finite with start_s <= end_s");
    const int idx = c.KeywordIndex(kw.word);
    if (idx >= 0) p.keywords.emplace_back(idx, kw);
  }
  std::sort(p.keywords.begin(), p.keywords.end(),
            [](const auto& a, const auto& b) { return a.second.end_s < b.second.end_s; });
  p.blend = o.blend_frames > 0 ? o.blend_frames : DefaultBlendFrames(dt);
  return p;
}

// Plays (segment, offsets) → motion, with angular-speed statistics.
Status Assemble(const Controller& c, const std::vector<std::pair<int, int>>& path, int blend,
                const SynthesisOptions& o, SynthesisResult* r) {
  const motion::FootPlantParams& feet = o.feet;
  const SegmentLibrary& L = c.segments();
  r->clip.skeleton = L.library->skeleton;
  r->clip.frame_time_s = c.frame_time_s();
  r->clip.frames.resize(static_cast<Eigen::Index>(path.size()), L.library->skeleton.num_channels());
  const double dt = c.frame_time_s();
  FrameAssembler fa(L, blend, feet, static_cast<int>(std::lround(o.start_s / dt)));
  // The last end_s: back to rest (a transition over 70 % of it, then held).
  const int end_frames = std::min(static_cast<int>(path.size()) - 1, static_cast<int>(std::lround(o.end_s / dt)));
  const int rest_transition = std::max(1, static_cast<int>(std::lround(0.7 * end_frames)));
  // A skeleton without legs has no feet to plant; anything else is an error.
  if (!fa.feet_status().ok() && !absl::IsFailedPrecondition(fa.feet_status())) return fa.feet_status();
  r->feet_planted = fa.plants_feet();
  r->feet_note = std::string(fa.feet_status().message());
  for (size_t t = 0; t < path.size(); ++t) {
    std::span<double> out(r->clip.frames.data() + static_cast<Eigen::Index>(t) * r->clip.frames.cols(),
                          static_cast<size_t>(r->clip.frames.cols()));
    if (end_frames > 0 && static_cast<int>(t) >= static_cast<int>(path.size()) - end_frames) {
      fa.NextRest(rest_transition, out);
    } else {
      fa.Next(path[t].first, path[t].second, out);
    }
  }
  r->max_transition_dps = fa.max_transition_dps();
  r->max_inside_dps = fa.max_inside_dps();
  r->library_p99_dps = L.angular_speed_p99_dps;
  return absl::OkStatus();
}

std::vector<SegmentPlayOut> PlaysOf(const Controller& c, const std::vector<std::pair<int, int>>& path,
                                    const std::vector<std::pair<int, std::string>>& served_at) {
  const SegmentLibrary& L = c.segments();
  const double dt = c.frame_time_s();
  std::vector<SegmentPlayOut> plays;
  size_t sk = 0;
  for (size_t t = 0; t < path.size(); ++t) {
    const auto [a, f] = path[t];
    if (plays.empty() || plays.back().segment != a || f != plays.back().last + 1) {
      if (!plays.empty()) {
        auto& p = plays.back();
        p.interrupted = p.last != L.segments[static_cast<size_t>(p.segment)].num_frames - 1;
      }
      SegmentPlayOut p;
      p.segment = a;
      p.first = p.last = f;
      p.start_s = static_cast<double>(t) * dt;
      while (sk < served_at.size() && served_at[sk].first < static_cast<int>(t)) ++sk;
      if (sk < served_at.size() && served_at[sk].first == static_cast<int>(t)) p.keyword = served_at[sk].second;
      plays.push_back(p);
    } else {
      plays.back().last = f;
    }
    plays.back().end_s = static_cast<double>(t + 1) * dt;
  }
  return plays;
}

}  // namespace

StatusOr<SynthesisResult> Synthesize(const Controller& c, const std::vector<BeliefSpan>& beliefs,
                                     const SynthesisOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(Prepared p, Prepare(c, beliefs, o));
  const SegmentLibrary& L = c.segments();
  const int N = L.num_segments(), E = L.num_end_points(), S = c.num_states(), M = c.num_tones(), T = p.frames;
  const double dt = c.frame_time_s();
  std::vector<int> base(static_cast<size_t>(N) + 1, 0);
  for (int a = 0; a < N; ++a) base[static_cast<size_t>(a) + 1] = base[static_cast<size_t>(a)] + L.segments[static_cast<size_t>(a)].num_frames;
  const int F = base[static_cast<size_t>(N)];
  std::vector<double> q(static_cast<size_t>(F), kInf), qn(static_cast<size_t>(F));
  // Run of unbroken library material on each cell's best path (frames), and
  // the longest a path may extend (SynthesisOptions::max_run_s).
  std::vector<int> run(static_cast<size_t>(F), 0), runn(static_cast<size_t>(F), 0);
  const int max_run = o.max_run_s > 0 ? std::max(1, static_cast<int>(std::lround(o.max_run_s / dt))) : 0;
  std::vector<int> run_in(static_cast<size_t>(N));
  // The path's memory (SynthesisOptions::recent_s), kept like the run: each
  // cell points at the newest record of its best path, a record being "this
  // segment was last shown at frame t", chained to the path's older records.
  // An entry from end point e may not go to a segment e's path showed in the
  // last recent_s (the segment e ends included). Records older than the
  // memory are cut off when the pool is compacted.
  struct Shown {
    int segment, t, older;
  };
  std::vector<Shown> shown;
  std::vector<int> mem(static_cast<size_t>(F), -1), memn(static_cast<size_t>(F), -1);
  const int recent = o.recent_s > 0 ? static_cast<int>(std::lround(o.recent_s / dt)) : 0;
  std::vector<long long> blocked(static_cast<size_t>(N), -1);
  std::vector<int> shown_of_e(static_cast<size_t>(E), -1);
  long long stamps = 0;
  // Marks (stamp) the segments end point e's path (cell memory m) showed
  // in the last `recent` frames; the segment itself is shown now.
  auto mark_recent = [&](int segment, int m, int t, long long stamp) {
    blocked[static_cast<size_t>(segment)] = stamp;
    for (; m >= 0 && t - shown[static_cast<size_t>(m)].t < recent; m = shown[static_cast<size_t>(m)].older)
      blocked[static_cast<size_t>(shown[static_cast<size_t>(m)].segment)] = stamp;
  };
  // The record of leaving end point e (cell) at frame t: made once per frame.
  auto record_of = [&](int e, size_t cell, int t) {
    int& r = shown_of_e[static_cast<size_t>(e)];
    if (r < 0 || shown[static_cast<size_t>(r)].t != t - 1) {
      shown.push_back({L.end_points[static_cast<size_t>(e)].segment, t - 1, mem[cell]});
      r = static_cast<int>(shown.size()) - 1;
    }
    return r;
  };
  // Keeps the records the cells can still reach within the memory.
  auto compact = [&](int t) {
    std::vector<int> remap(shown.size(), -1);
    std::vector<Shown> kept;
    std::function<int(int)> keep = [&](int m) -> int {
      if (m < 0 || t - shown[static_cast<size_t>(m)].t >= recent) return -1;
      if (remap[static_cast<size_t>(m)] >= 0) return remap[static_cast<size_t>(m)];
      const int older = keep(shown[static_cast<size_t>(m)].older);
      kept.push_back({shown[static_cast<size_t>(m)].segment, shown[static_cast<size_t>(m)].t, older});
      return remap[static_cast<size_t>(m)] = static_cast<int>(kept.size()) - 1;
    };
    // Cells no path reaches (q infinite) may hold records of an older pool.
    for (size_t i = 0; i < mem.size(); ++i) mem[i] = q[i] < kInf ? keep(mem[i]) : -1;
    shown.swap(kept);
    std::fill(shown_of_e.begin(), shown_of_e.end(), -1);
  };
  std::vector<double> cost(static_cast<size_t>(N));
  std::vector<int> bp0(static_cast<size_t>(T) * N, -1);
  struct SemBp {
    int t, segment, f, e, keyword;
  };
  std::vector<SemBp> sem_bp;
  std::vector<double> best_in(static_cast<size_t>(N));
  std::vector<int> arg_in(static_cast<size_t>(N));
  size_t step = 0;
  // Constraint frames: word end + deadline, per keyword event.
  std::vector<std::pair<int, int>> constraints;  // (frame, w)
  for (const auto& [k, ev] : p.keywords)
    constraints.emplace_back(std::min(T - 1, static_cast<int>(std::floor((ev.end_s + o.keyword_deadline_s) / dt))), k + 1);
  const double kHard = 1e6;
  for (int t = 0; t < T; ++t) {
    // A long recording's synthesis takes a while: the caller may stop it (every 10 s of motion).
    if (t % 300 == 0) KINEMO_RETURN_IF_ERROR(CheckCancel(o.cancel, "synthesis"));
    const double time = (t + 0.5) * dt;
    while (step + 1 < beliefs.size() && beliefs[step + 1].start_s <= time) ++step;
    const auto& g = beliefs[step].probabilities;
    for (int a = 0; a < N; ++a) {
      double v = 0;
      for (int m = 0; m < M; ++m) {
        if (p.style[static_cast<size_t>(m)] == 0) continue;
        const double* d = c.delta(m).data() + static_cast<Eigen::Index>(a) * S;
        double s = 0;
        for (int i = 0; i < S; ++i) s += g[static_cast<size_t>(i)] * d[i];
        v += p.style[static_cast<size_t>(m)] * s;
      }
      cost[static_cast<size_t>(a)] = v;
    }
    if (t == 0) {
      for (int a = 0; a < N; ++a) {
        qn[static_cast<size_t>(base[static_cast<size_t>(a)])] = cost[static_cast<size_t>(a)];
        runn[static_cast<size_t>(base[static_cast<size_t>(a)])] = 1;
      }
    } else {
      std::fill(qn.begin(), qn.end(), kInf);
      for (int a = 0; a < N; ++a)
        for (int f = 1; f < L.segments[static_cast<size_t>(a)].num_frames; ++f) {
          const size_t from = static_cast<size_t>(base[static_cast<size_t>(a)] + f - 1);
          // A run may not go on past max_run: the path must have left at an
          // end point before.
          if (max_run > 0 && run[from] >= max_run) continue;
          qn[from + 1] = q[from] + cost[static_cast<size_t>(a)];
          runn[from + 1] = run[from] + 1;
          memn[from + 1] = mem[from];
        }
      // Entries at frame 0: best[a] = min_e Q(e) + S(e, a), one contiguous
      // row of S per source end point.
      // With the memory first; if it rules out every entry at every end
      // point and no play goes on (a library of a few segments), without it.
      auto enter = [&](bool remember) {
        std::fill(best_in.begin(), best_in.end(), kInf);
        std::fill(arg_in.begin(), arg_in.end(), -1);
        bool any = false;
        for (int e = 0; e < E; ++e) {
          const auto& ep = L.end_points[static_cast<size_t>(e)];
          const size_t cell = static_cast<size_t>(base[static_cast<size_t>(ep.segment)] + ep.frame);
          const double v = q[cell];
          if (!(v < kInf)) continue;
          // The true successor continues the run: not past max_run.
          const int next = ep.last ? L.segments[static_cast<size_t>(ep.segment)].next : -1;
          const bool chain_ok = !(max_run > 0 && run[cell] >= max_run);
          const long long stamp = ++stamps;
          if (remember) mark_recent(ep.segment, mem[cell], t, stamp);
          const float* row = L.transition.data() + static_cast<size_t>(e) * N;
          for (int a = 0; a < N; ++a) {
            if (a == next && !chain_ok) continue;
            // As the online policy: the successor too, if shown recently.
            if (remember && blocked[static_cast<size_t>(a)] == stamp) continue;
            const double x = v + row[a];
            if (x < best_in[static_cast<size_t>(a)]) {
              best_in[static_cast<size_t>(a)] = x;
              arg_in[static_cast<size_t>(a)] = e;
              run_in[static_cast<size_t>(a)] = a == next ? run[cell] + 1 : 1;
              any = true;
            }
          }
        }
        return any;
      };
      if (!enter(recent > 0) && recent > 0 &&
          std::none_of(qn.begin(), qn.end(), [](double x) { return x < kInf; }))
        enter(false);
      for (int a = 0; a < N; ++a) {
        const size_t cell0 = static_cast<size_t>(base[static_cast<size_t>(a)]);
        qn[cell0] = best_in[static_cast<size_t>(a)] + cost[static_cast<size_t>(a)];
        runn[cell0] = run_in[static_cast<size_t>(a)];
        bp0[static_cast<size_t>(t) * N + a] = arg_in[static_cast<size_t>(a)];
        if (recent > 0 && arg_in[static_cast<size_t>(a)] >= 0) {
          const int e = arg_in[static_cast<size_t>(a)];
          const auto& ep = L.end_points[static_cast<size_t>(e)];
          memn[cell0] = record_of(e, static_cast<size_t>(base[static_cast<size_t>(ep.segment)] + ep.frame), t);
        }
      }
      // Semantic entries (at f'_start(e, b), as the online table) in the
      // second before each keyword's deadline.
      for (const auto& [tc, w] : constraints) {
        if (t > tc || t < tc - static_cast<int>(1.0 / dt)) continue;
        for (int e = 0; e < E; ++e) {
          const auto& ep = L.end_points[static_cast<size_t>(e)];
          const double v = q[static_cast<size_t>(base[static_cast<size_t>(ep.segment)] + ep.frame)];
          if (!(v < kInf)) continue;
          for (const auto& se : c.SemanticEntries(w, e)) {
            if (se.start == 0) continue;  // a normal entry
            const size_t idx = static_cast<size_t>(base[static_cast<size_t>(se.segment)] + se.start);
            const double x = v + se.cost + cost[static_cast<size_t>(se.segment)];
            if (x < qn[idx]) {
              qn[idx] = x;
              runn[idx] = 1;
              if (recent > 0)
                memn[idx] = record_of(e, static_cast<size_t>(base[static_cast<size_t>(ep.segment)] + ep.frame), t);
              sem_bp.push_back({t, se.segment, se.start, e, w - 1});
            }
          }
        }
      }
    }
    for (const auto& [tc, w] : constraints) {
      if (tc != t) continue;
      for (int a = 0; a < N; ++a)
        if (!c.Matches(a, w))
          for (int f = 0; f < L.segments[static_cast<size_t>(a)].num_frames; ++f) qn[static_cast<size_t>(base[static_cast<size_t>(a)] + f)] += kHard;
    }
    q.swap(qn);
    run.swap(runn);
    if (recent > 0) {
      mem.swap(memn);
      if (shown.size() > 4 * static_cast<size_t>(F) + 4096) compact(t + 1);
    }
  }
  // Backtrack.
  int cur = static_cast<int>(std::min_element(q.begin(), q.end()) - q.begin());
  SynthesisResult r;
  r.total_cost = q[static_cast<size_t>(cur)];
  int a = static_cast<int>(std::upper_bound(base.begin(), base.end(), cur) - base.begin()) - 1;
  int f = cur - base[static_cast<size_t>(a)];
  std::vector<std::pair<int, int>> path(static_cast<size_t>(T));
  std::vector<std::pair<int, std::string>> served;
  for (int t = T - 1; t >= 0; --t) {
    path[static_cast<size_t>(t)] = {a, f};
    if (t == 0) break;
    int src = -1;
    if (f > 0) {
      // The last semantic record for (t, a, f) is the one that won.
      for (auto it = sem_bp.rbegin(); it != sem_bp.rend() && it->t >= t; ++it) {
        if (it->t == t && it->segment == a && it->f == f) {
          src = it->e;
          served.emplace_back(t, c.keywords()[static_cast<size_t>(it->keyword)]);
          break;
        }
      }
      if (src < 0) {
        --f;
        continue;
      }
    } else {
      src = bp0[static_cast<size_t>(t) * N + a];
      if (src < 0) break;
    }
    const auto& ep = L.end_points[static_cast<size_t>(src)];
    a = ep.segment;
    f = ep.frame;
  }
  std::sort(served.begin(), served.end());
  r.plays = PlaysOf(c, path, served);
  // Entries at frame 0 of a matching stroke inside a keyword window also serve it.
  for (auto& play : r.plays) {
    if (!play.keyword.empty()) continue;
    for (const auto& [k, ev] : p.keywords) {
      if (c.Matches(play.segment, k + 1) && play.end_s > ev.start_s && play.start_s <= ev.end_s + o.keyword_deadline_s + dt) {
        play.keyword = c.keywords()[static_cast<size_t>(k)];
        break;
      }
    }
  }
  KINEMO_RETURN_IF_ERROR(Assemble(c, path, p.blend, o, &r));
  r.compute_s = Seconds(t0);
  return r;
}

StatusOr<SynthesisResult> RunOnline(const Controller& c, const std::vector<BeliefSpan>& beliefs,
                                    const SynthesisOptions& o, std::vector<double>* decide_us) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(Prepared p, Prepare(c, beliefs, o));
  const SegmentLibrary& L = c.segments();
  const double dt = c.frame_time_s();
  if (!(o.min_play_s >= 0 && o.min_play_s <= 10)) return InvalidField("min_play_s", o.min_play_s, " is outside [0, 10] s");
  Policy policy(c, o.min_play_s, o.max_run_s, o.recent_s);
  KINEMO_RETURN_IF_ERROR(policy.SetStyle(p.style));
  size_t next_belief = 0, next_kw = 0;
  std::vector<std::pair<int, int>> path;
  std::vector<std::pair<int, std::string>> served;
  path.reserve(static_cast<size_t>(p.frames));
  int seg = -1, frame = 0, end_point = 0;
  for (int t = 0; t < p.frames; ++t) {
    const double time = t * dt;
    bool got = false;
    while (next_belief < beliefs.size() && beliefs[next_belief].start_s <= time + 1e-9) {
      KINEMO_RETURN_IF_ERROR(policy.SetBelief(beliefs[next_belief].probabilities));
      ++next_belief;
      got = true;
    }
    if (!got && t > 0) policy.Advance();
    while (next_kw < p.keywords.size() && p.keywords[next_kw].second.end_s <= time + 1e-9) {
      KINEMO_RETURN_IF_ERROR(policy.SetKeyword(p.keywords[next_kw].first));
      ++next_kw;
    }
    const int pending = policy.pending_keyword();
    Decision d;
    bool decided = false;
    const auto td = std::chrono::steady_clock::now();
    if (seg < 0) {
      d = policy.Start();
      decided = true;
    } else if (frame == L.segments[static_cast<size_t>(seg)].ends[static_cast<size_t>(L.end_points[static_cast<size_t>(end_point)].k)]) {
      d = policy.Decide(end_point);
      decided = true;
    } else {
      ++frame;
    }
    if (decided) {
      const double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - td).count();
      if (decide_us) decide_us->push_back(us);
      seg = d.segment;
      frame = d.start;
      end_point = d.end_point;
      if (d.keyword >= 0 && pending >= 0 && !d.continuation) served.emplace_back(t, c.keywords()[static_cast<size_t>(d.keyword)]);
    }
    path.emplace_back(seg, frame);
  }
  SynthesisResult r;
  r.plays = PlaysOf(c, path, served);
  KINEMO_RETURN_IF_ERROR(Assemble(c, path, p.blend, o, &r));
  r.compute_s = Seconds(t0);
  return r;
}

StatusOr<SynthesisResult> SynthesizeRandom(const Controller& c, const std::vector<BeliefSpan>& beliefs,
                                           const SynthesisOptions& o, std::uint64_t seed) {
  const auto t0 = std::chrono::steady_clock::now();
  KINEMO_ASSIGN_OR_RETURN(Prepared p, Prepare(c, beliefs, o));
  const SegmentLibrary& L = c.segments();
  const int n = L.num_segments();
  if (n < 1) return absl::FailedPreconditionError("controller: the library has no segments");
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, n - 1);
  std::vector<std::pair<int, int>> path;
  path.reserve(static_cast<size_t>(p.frames));
  int seg = pick(rng), frame = 0;
  for (int t = 0; t < p.frames; ++t) {
    if (frame >= L.segments[static_cast<size_t>(seg)].num_frames) {
      int next = pick(rng);
      if (n > 1)
        while (next == seg) next = pick(rng);
      seg = next;
      frame = 0;
    }
    path.emplace_back(seg, frame++);
  }
  SynthesisResult r;
  r.plays = PlaysOf(c, path, {});
  KINEMO_RETURN_IF_ERROR(Assemble(c, path, p.blend, o, &r));
  r.compute_s = Seconds(t0);
  return r;
}

StatusOr<std::vector<double>> StyleFromWeights(const Controller& c,
                                               const std::vector<std::pair<std::string, double>>& weights,
                                               double gesture_emphasis) {
  const double e = gesture_emphasis;
  if (!std::isfinite(e) || e < -1 || e > 1) return InvalidField("style.gesture_emphasis", e, " must be in [-1, 1]");
  std::vector<double> out(static_cast<size_t>(c.num_tones()), 0.0);
  if (weights.empty()) {
    const int n = c.ToneIndex(c.params().neutral_tone);
    out[static_cast<size_t>(n >= 0 ? n : 0)] = 1;
  } else {
    double sum = 0;
    for (const auto& [tone, w] : weights) {
      const int i = Controller::IsEmphasisTone(tone) ? -1 : c.ToneIndex(tone);
      if (i < 0) return InvalidField("style.tone_weights", "unknown tone '", tone, "'");
      if (!std::isfinite(w) || w < 0) return InvalidField("style.tone_weights", "'", tone, "' must be finite and >= 0");
      out[static_cast<size_t>(i)] += w;
      sum += w;
    }
    if (!(sum > 0)) return InvalidField("style.tone_weights", "sum to 0");
    for (double& v : out) v /= sum;
  }
  if (e == 0) return out;
  for (int m = 0; m < c.num_tones(); ++m) {
    const double d = out[static_cast<size_t>(m)];
    if (d == 0 || Controller::IsEmphasisTone(c.tones()[static_cast<size_t>(m)])) continue;
    const int x = c.EmphasisIndex(m, e);
    if (x < 0) continue;  // built before emphasis existed: the tone mix as it is
    out[static_cast<size_t>(m)] = (1 - std::abs(e)) * d;
    out[static_cast<size_t>(x)] = std::abs(e) * d;
  }
  return out;
}

}  // namespace kinemo::planner::controller
