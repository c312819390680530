// The thesis' evaluation (Tables 3.2-3.3, Figs. 3.14-3.15): for every split
// profile and threshold, connectivity, TBF, response, cost and LM.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <time.h>

#include "common/parallel/parallel.h"
#include "services/planner/locomotion/locomotion.h"

namespace kinemo::planner::locomotion {
namespace {
double ThreadCpuUs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e6 + static_cast<double>(ts.tv_nsec) * 1e-3;
}
}  // namespace

StatusOr<std::vector<EvaluationRow>> Evaluate(std::shared_ptr<const LocomotionData> data,
                                              const EvaluationOptions& options) {
  if (options.request_stride < 1 || options.request_stride > 1000) {
    return InvalidField("request_stride", "must be in [1, 1000]");
  }
  if (options.threads < 0 || options.threads > 64) return InvalidField("threads", "must be in [0, 64]");
  std::vector<SplitProfile> profiles = options.profiles;
  if (profiles.empty()) {
    for (const auto& name : BuiltinProfileNames()) {
      KINEMO_ASSIGN_OR_RETURN(SplitProfile p, BuiltinProfile(name));
      profiles.push_back(std::move(p));
    }
  }
  for (const auto& p : profiles) KINEMO_RETURN_IF_ERROR(ValidateProfile(p));
  std::vector<double> thresholds = options.thresholds;
  if (thresholds.empty()) {
    for (int k = 0; k <= 18; ++k) thresholds.push_back(0.05 + 0.025 * k);
  }
  if (thresholds.size() > 1000) return InvalidField("thresholds", "at most 1000");
  for (double t : thresholds) {
    if (!(t > 0) || !std::isfinite(t)) return InvalidField("thresholds", "must be > 0");
  }
  KINEMO_RETURN_IF_ERROR(ResolveParams(options.params).status());
  const int threads = parallel::ResolveThreads(options.threads);
  const int nclips = static_cast<int>(data->clip_begin.size()) - 1;
  const size_t np = profiles.size();
  // Request frames (not the last frame of a clip), by clip.
  std::vector<int> requests;
  std::vector<int> clip_requests(static_cast<size_t>(nclips) + 1, 0);  // first request of each clip
  for (int c = 0; c < nclips; ++c) {
    clip_requests[static_cast<size_t>(c)] = static_cast<int>(requests.size());
    for (int g = data->clip_begin[static_cast<size_t>(c)]; g + 1 < data->clip_begin[static_cast<size_t>(c) + 1];
         g += options.request_stride) {
      requests.push_back(g);
    }
  }
  clip_requests[static_cast<size_t>(nclips)] = static_cast<int>(requests.size());

  // Shared across thresholds: every distinct part's candidate transitions.
  std::vector<std::vector<Chain>> distinct;
  for (const auto& p : profiles) {
    for (const auto& chains : p.parts) {
      if (std::find(distinct.begin(), distinct.end(), chains) == distinct.end()) distinct.push_back(chains);
    }
  }
  std::vector<std::shared_ptr<const PartCandidates>> candidates(distinct.size());
  parallel::ParallelFor(static_cast<int>(distinct.size()), threads, [&](int i, int) {
    if (Stopped(options.cancel)) return;
    candidates[static_cast<size_t>(i)] = FindPartCandidates(*data, distinct[static_cast<size_t>(i)]);
  });
  KINEMO_RETURN_IF_ERROR(CheckCancel(options.cancel, "evaluation"));

  // One plan per (row, request, target clip), kept until the row's means are
  // summed in the order of requests then targets (so that they do not
  // depend on the order in which the threads finish).
  struct Outcome {
    bool ok = false;
    int total_frames = 0, response_frames = 0;
    double cost = 0, wall_us = 0, cpu_us = 0;
  };
  const size_t plans = requests.size() * static_cast<size_t>(nclips);
  std::vector<EvaluationRow> rows(np * thresholds.size());
  std::vector<std::vector<Outcome>> outcomes(np, std::vector<Outcome>(plans));
  for (size_t ti = 0; ti < thresholds.size(); ++ti) {
    KINEMO_RETURN_IF_ERROR(CheckCancel(options.cancel, "evaluation"));
    GraphParams params = options.params;
    params.threshold = thresholds[ti];
    std::vector<std::shared_ptr<const LocomotionGraph>> graphs(np);
    std::vector<Status> built(np);
    parallel::ParallelFor(static_cast<int>(np), threads, [&](int p, int) {
      auto g = LocomotionGraph::Build(data, profiles[static_cast<size_t>(p)], params, candidates);
      if (g.ok()) {
        graphs[static_cast<size_t>(p)] = *std::move(g);
      } else {
        built[static_cast<size_t>(p)] = g.status();
      }
    });
    for (const Status& st : built) KINEMO_RETURN_IF_ERROR(st);
    // Work items: (source clip, target clip), every profile at once, so
    // that searches shared by profiles and by requests are made once.
    const int items = nclips * nclips;
    parallel::ParallelFor(items, threads, [&](int item, int) {
      const int c = item / nclips, t = item % nclips;
      if (c == t || Stopped(options.cancel)) return;
      SharedPlanner planner(graphs);
      Transition tr;
      for (int i = clip_requests[static_cast<size_t>(c)]; i < clip_requests[static_cast<size_t>(c) + 1]; ++i) {
        const int g = requests[static_cast<size_t>(i)];
        for (size_t p = 0; p < np; ++p) {
          Outcome& o = outcomes[p][static_cast<size_t>(i) * static_cast<size_t>(nclips) + static_cast<size_t>(t)];
          const double c0 = ThreadCpuUs();
          const auto t0 = std::chrono::steady_clock::now();
          o.ok = planner.Plan(p, g, t, &tr).ok();
          if (o.ok) {
            o.total_frames = tr.total_frames;
            o.response_frames = tr.response_frames;
            o.cost = TransitionCost(*graphs[p], tr);
          }
          o.cpu_us = ThreadCpuUs() - c0;
          o.wall_us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
        }
      }
    });
    for (size_t p = 0; p < np; ++p) {
      const LocomotionGraph& graph = *graphs[p];
      EvaluationRow& row = rows[p * thresholds.size() + ti];
      row.method = profiles[p].name;
      row.threshold = thresholds[ti];
      row.connected_clips = graph.connected_clips();
      row.connectivity = graph.connectivity();
      row.build_s = graph.build_s();
      const size_t cells = static_cast<size_t>(nclips) * static_cast<size_t>(nclips);
      std::vector<double> sum_total(cells, 0), sum_response(cells, 0);
      std::vector<int> count(cells, 0);
      double sum_cost = 0;
      int attempts = 0;
      for (size_t i = 0; i < requests.size(); ++i) {
        const int c = data->clip_of[static_cast<size_t>(requests[i])];
        for (int t = 0; t < nclips; ++t) {
          if (t == c) continue;
          const Outcome& o = outcomes[p][i * static_cast<size_t>(nclips) + static_cast<size_t>(t)];
          ++attempts;
          row.search_us.push_back(o.wall_us);
          row.search_cpu_us.push_back(o.cpu_us);
          if (!o.ok) continue;
          const size_t cell = static_cast<size_t>(c) * static_cast<size_t>(nclips) + static_cast<size_t>(t);
          sum_total[cell] += o.total_frames;
          sum_response[cell] += o.response_frames;
          ++count[cell];
          sum_cost += o.cost;
        }
      }
      int ok = 0;
      double all_total = 0, all_response = 0;
      for (size_t k = 0; k < cells; ++k) {
        ok += count[k];
        all_total += sum_total[k];
        all_response += sum_response[k];
      }
      row.transitions = ok;
      row.success_rate = attempts > 0 ? static_cast<double>(ok) / attempts : 0;
      const double nan = std::numeric_limits<double>::quiet_NaN();
      row.tbf_frames = ok > 0 ? all_total / ok : nan;
      row.response_frames = ok > 0 ? all_response / ok : nan;
      row.cost = ok > 0 ? sum_cost / ok : nan;
      if (options.maneuverability) {
        row.maneuverability.assign(cells, nan);
        row.response_matrix.assign(cells, nan);
        for (size_t k = 0; k < cells; ++k) {
          if (count[k] == 0) continue;
          row.maneuverability[k] = sum_total[k] / count[k];
          row.response_matrix[k] = sum_response[k] / count[k];
        }
      }
    }
  }
  return rows;
}

double CubeAngleToSpeed(double angle_deg) {
  if (!std::isfinite(angle_deg)) return 0;
  double a = std::fmod(std::abs(angle_deg), 360.0);
  if (a > 180) a = 360 - a;
  if (a <= 45) return 0;
  return 1.55 + (5.55 - 1.55) * a / 180.0;
}

}  // namespace kinemo::planner::locomotion
