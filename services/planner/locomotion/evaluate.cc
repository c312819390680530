// The thesis' evaluation (Tables 3.2-3.3, Figs. 3.14-3.15): for every split
// profile and threshold, connectivity, TBF, response, cost and LM.
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <thread>
#include <time.h>

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
  if (options.threads < 1 || options.threads > 64) return InvalidField("threads", "must be in [1, 64]");
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
  const int nclips = static_cast<int>(data->clip_begin.size()) - 1;
  // Request frames (not the last frame of a clip).
  std::vector<int> requests;
  for (int c = 0; c < nclips; ++c) {
    for (int g = data->clip_begin[static_cast<size_t>(c)]; g + 1 < data->clip_begin[static_cast<size_t>(c) + 1];
         g += options.request_stride) {
      requests.push_back(g);
    }
  }
  std::vector<EvaluationRow> rows;
  for (const auto& profile : profiles) {
    for (double threshold : thresholds) {
      GraphParams params = options.params;
      params.threshold = threshold;
      KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const LocomotionGraph> graph,
                              LocomotionGraph::Build(data, profile, params));
      EvaluationRow row;
      row.method = profile.name;
      row.threshold = threshold;
      row.connected_clips = graph->connected_clips();
      row.connectivity = graph->connectivity();
      row.build_s = graph->build_s();
      const size_t cells = static_cast<size_t>(nclips) * static_cast<size_t>(nclips);
      std::vector<double> sum_total(cells, 0), sum_response(cells, 0);
      std::vector<int> count(cells, 0);
      double sum_cost = 0;
      int attempts = 0;
      std::mutex mu;
      std::atomic<size_t> next{0};
      auto worker = [&]() {
        SearchWorkspace ws;
        Transition tr;
        std::vector<double> local_total(cells, 0), local_response(cells, 0), local_us, local_cpu;
        std::vector<int> local_count(cells, 0);
        double local_cost = 0;
        int local_attempts = 0;
        for (size_t i = next++; i < requests.size(); i = next++) {
          const int g = requests[i];
          const int c = data->clip_of[static_cast<size_t>(g)];
          for (int t = 0; t < nclips; ++t) {
            if (t == c) continue;
            ++local_attempts;
            const double c0 = ThreadCpuUs();
            const auto t0 = std::chrono::steady_clock::now();
            const Status st = PlanTransition(*graph, g, t, &ws, &tr);
            local_cpu.push_back(ThreadCpuUs() - c0);
            local_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
            if (!st.ok()) continue;
            const size_t cell = static_cast<size_t>(c) * static_cast<size_t>(nclips) + static_cast<size_t>(t);
            local_total[cell] += tr.total_frames;
            local_response[cell] += tr.response_frames;
            ++local_count[cell];
            local_cost += TransitionCost(*graph, tr);
          }
        }
        std::lock_guard lock(mu);
        for (size_t k = 0; k < cells; ++k) {
          sum_total[k] += local_total[k];
          sum_response[k] += local_response[k];
          count[k] += local_count[k];
        }
        sum_cost += local_cost;
        attempts += local_attempts;
        row.search_us.insert(row.search_us.end(), local_us.begin(), local_us.end());
        row.search_cpu_us.insert(row.search_cpu_us.end(), local_cpu.begin(), local_cpu.end());
      };
      std::vector<std::thread> threads;
      for (int k = 1; k < options.threads; ++k) threads.emplace_back(worker);
      worker();
      for (auto& th : threads) th.join();
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
      rows.push_back(std::move(row));
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
