// `kinemo locomotion ...`: Body Part Motion Graphs (thesis ch. 3) offline.
//
//   kinemo locomotion evaluate --clips DIR [--json] [--profiles SMG,SP5,...]
//       [--thresholds A:B:STEP | --thresholds T,T,...] [--stride N] [--threads N] [--max-transitions N]
//       [--csv F] [--png F] [--lm F]
//     Tables 3.2-3.3 and Figs. 3.14-3.15: per split profile and threshold,
//     connected clips, TBF, response, connectivity and cost, in frames at the
//     clips' rate. --json prints [{method, threshold, connected_clips,
//     tbf_frames, response_frames, connectivity, cost}].
//   kinemo locomotion plan --clips DIR --from CLIP --frame N --to CLIP
//       [--profile SP5] [--threshold T] [--out F.bvh]
//     One transition: metrics as JSON, the full-body motion as BVH.
//   kinemo locomotion drive --clips DIR --idle C --walk C [--run C]
//       (--speed S | --cube-angle DEG) [--target X,Y] [--path X,Y;X,Y;...]
//       [--seconds S] [--profile SP5] [--threshold T] [--out F.bvh] [--json]
//     The AvatAR offline: walks to the target, prints the trajectory summary.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "common/image/png.h"
#include "common/motion/bvh.h"
#include "services/cli/commands.h"
#include "services/planner/library/library.h"
#include "services/planner/locomotion/locomotion.h"

namespace kinemo::cli {
namespace {
namespace cmd_locomotion {  // this file's own helpers (the unity build puts files together)

namespace loco = planner::locomotion;

[[noreturn]] void Fail(const Status& status) {
  FailCommand("locomotion", status, {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound});
}

template <typename T>
T OrFail(StatusOr<T> v) {
  if (!v.ok()) Fail(v.status());
  return *std::move(v);
}

int g_max_transitions = 0;  // --max-transitions

std::shared_ptr<const loco::LocomotionData> LoadData(const std::vector<std::string>& clips, bool quiet) {
  planner::LibrarySources sources;
  sources.paths = clips;
  auto lib = OrFail(planner::LoadLibrary("locomotion", sources));
  if (!quiet) {
    for (const auto& w : lib->warnings) std::cerr << "note: " << w << "\n";
  }
  return OrFail(loco::BuildLocomotionData(lib, {}));
}

std::vector<double> ParseThresholds(const std::string& text) {
  std::vector<double> out;
  if (text.empty()) return out;
  if (text.find(':') != std::string::npos) {
    double a = 0, b = 0, step = 0;
    char c1 = 0, c2 = 0;
    std::istringstream in(text);
    if (!(in >> a >> c1 >> b >> c2 >> step) || c1 != ':' || c2 != ':' || step <= 0 || b < a) {
      Fail(InvalidField("--thresholds", "expected A:B:STEP"));
    }
    for (int k = 0; a + k * step <= b + 1e-9; ++k) out.push_back(std::round((a + k * step) * 1e6) / 1e6);
    return out;
  }
  std::istringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    try {
      out.push_back(std::stod(item));
    } catch (...) {
      Fail(InvalidField("--thresholds", "not a number: " + item));
    }
  }
  return out;
}

std::vector<std::string> Split(const std::string& text, char sep) {
  std::vector<std::string> out;
  std::istringstream in(text);
  std::string item;
  while (std::getline(in, item, sep)) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

nlohmann::json Num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

// Figs. 3.14-3.15 style: four panels (connectivity, TBF, response, cost) vs threshold.
void DrawPlot(const std::vector<loco::EvaluationRow>& rows, double fps, const std::string& path) {
  const int pw = 520, ph = 340, margin = 55;
  cv::Mat img(2 * ph, 2 * pw, CV_8UC3, cv::Scalar(255, 255, 255));
  std::vector<std::string> methods;
  for (const auto& r : rows) {
    if (std::find(methods.begin(), methods.end(), r.method) == methods.end()) methods.push_back(r.method);
  }
  const cv::Scalar colors[] = {{0, 0, 0}, {200, 0, 0}, {0, 150, 0}, {0, 0, 220}, {200, 0, 200}, {0, 160, 200}, {120, 80, 0}};
  double tmin = 1e9, tmax = -1e9;
  for (const auto& r : rows) {
    tmin = std::min(tmin, r.threshold);
    tmax = std::max(tmax, r.threshold);
  }
  if (tmax <= tmin) tmax = tmin + 1;
  struct Panel {
    const char* title;
    double (*get)(const loco::EvaluationRow&);
  };
  const Panel panels[] = {
      {"connectivity (fraction of frames)", [](const loco::EvaluationRow& r) { return r.connectivity; }},
      {"TBF (frames)", [](const loco::EvaluationRow& r) { return r.tbf_frames; }},
      {"response (frames)", [](const loco::EvaluationRow& r) { return r.response_frames; }},
      {"transition cost", [](const loco::EvaluationRow& r) { return r.cost; }},
  };
  for (int k = 0; k < 4; ++k) {
    const int ox = (k % 2) * pw, oy = (k / 2) * ph;
    double vmax = 0;
    for (const auto& r : rows) {
      const double v = panels[k].get(r);
      if (std::isfinite(v)) vmax = std::max(vmax, v);
    }
    if (vmax <= 0) vmax = 1;
    const int x0 = ox + margin, x1 = ox + pw - 15, y0 = oy + ph - 40, y1 = oy + 30;
    cv::rectangle(img, {x0, y1}, {x1, y0}, {160, 160, 160});
    cv::putText(img, panels[k].title, {x0, oy + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 0}, 1);
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.3g", vmax);
    cv::putText(img, buf, {ox + 2, y1 + 10}, cv::FONT_HERSHEY_SIMPLEX, 0.38, {0, 0, 0}, 1);
    std::snprintf(buf, sizeof buf, "threshold %.3f .. %.3f (%.0f fps)", tmin, tmax, fps);
    cv::putText(img, buf, {x0, y0 + 28}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0}, 1);
    for (size_t m = 0; m < methods.size(); ++m) {
      cv::Point last(-1, -1);
      for (const auto& r : rows) {
        if (r.method != methods[m]) continue;
        const double v = panels[k].get(r);
        if (!std::isfinite(v)) {
          last = {-1, -1};
          continue;
        }
        const cv::Point pt(x0 + static_cast<int>((r.threshold - tmin) / (tmax - tmin) * (x1 - x0)),
                           y0 - static_cast<int>(v / vmax * (y0 - y1)));
        if (last.x >= 0) cv::line(img, last, pt, colors[m % 7], m == 0 ? 2 : 1, cv::LINE_AA);
        cv::circle(img, pt, 2, colors[m % 7], -1);
        last = pt;
      }
      if (k == 0) {
        cv::putText(img, methods[m], {x1 - 60, y0 - 10 - 16 * static_cast<int>(m)}, cv::FONT_HERSHEY_SIMPLEX, 0.45,
                    colors[m % 7], 1);
      }
    }
  }
  const Status written = image::WritePngFile(path, {img.data, img.cols, img.rows, img.channels(), img.step, true});
  if (!written.ok()) Fail(Annotate(written, "--png"));
}

void RunEvaluate(const std::vector<std::string>& clips, bool json, const std::string& profiles,
                 const std::string& thresholds, int stride, int threads, const std::string& csv,
                 const std::string& png, const std::string& lm_path) {
  auto data = LoadData(clips, json);
  loco::EvaluationOptions options;
  for (const auto& name : Split(profiles, ',')) options.profiles.push_back(OrFail(loco::BuiltinProfile(name)));
  options.thresholds = ParseThresholds(thresholds);
  options.request_stride = stride;
  options.threads = threads;
  options.maneuverability = !lm_path.empty();
  options.params.max_transitions_per_frame = g_max_transitions;
  const auto t0 = std::chrono::steady_clock::now();
  auto rows = OrFail(loco::Evaluate(data, options));
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (json) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& r : rows) {
      out.push_back({{"method", r.method},
                     {"threshold", r.threshold},
                     {"connected_clips", r.connected_clips},
                     {"tbf_frames", Num(r.tbf_frames)},
                     {"response_frames", Num(r.response_frames)},
                     {"connectivity", Num(r.connectivity)},
                     {"cost", Num(r.cost)}});
    }
    std::cout << out.dump(1) << "\n";
  } else {
    const int nclips = static_cast<int>(data->clip_begin.size()) - 1;
    std::cout << "clips (" << data->fps << " fps, " << data->num_frames << " frames):";
    for (const auto& c : data->library->clips) std::cout << " " << c.name;
    std::cout << "\nmethod threshold connected/" << nclips
              << " connectivity tbf_frames response_frames cost success search_p50_us search_p99_us build_s\n";
    for (const auto& r : rows) {
      std::printf("%-5s %.3f %d %.3f %.2f %.2f %.4f %.3f %.1f %.1f %.3f\n", r.method.c_str(), r.threshold,
                  r.connected_clips, r.connectivity, r.tbf_frames, r.response_frames, r.cost, r.success_rate,
                  Percentile(r.search_us, 0.5), Percentile(r.search_us, 0.99), r.build_s);
    }
    std::vector<double> all_us, all_cpu;
    double build = 0;
    for (const auto& r : rows) {
      all_us.insert(all_us.end(), r.search_us.begin(), r.search_us.end());
      all_cpu.insert(all_cpu.end(), r.search_cpu_us.begin(), r.search_cpu_us.end());
      build += r.build_s;
    }
    double clip_minutes = 0;
    for (const auto& c : data->library->clips) clip_minutes += c.clip.duration_s() / 60;
    std::printf("searches %zu: wall p50 %.1f us, p99 %.1f us, max %.1f us; thread CPU p50 %.1f us, p99 %.1f us, "
                "max %.1f us; graph build %.3f s per clip-minute (mean of %zu); evaluation wall %.1f s\n",
                all_us.size(), Percentile(all_us, 0.5), Percentile(all_us, 0.99), Percentile(all_us, 1.0),
                Percentile(all_cpu, 0.5), Percentile(all_cpu, 0.99), Percentile(all_cpu, 1.0),
                rows.empty() ? 0 : build / static_cast<double>(rows.size()) / clip_minutes, rows.size(), wall);
  }
  if (!csv.empty()) {
    std::ofstream f(csv);
    f << "method,threshold,connected_clips,connectivity,tbf_frames,response_frames,cost,success_rate,transitions,"
         "search_p99_us,search_cpu_p99_us,build_s,frame_rate_hz\n";
    for (const auto& r : rows) {
      f << r.method << "," << r.threshold << "," << r.connected_clips << "," << r.connectivity << "," << r.tbf_frames
        << "," << r.response_frames << "," << r.cost << "," << r.success_rate << "," << r.transitions << ","
        << Percentile(r.search_us, 0.99) << "," << Percentile(r.search_cpu_us, 0.99) << "," << r.build_s << "," << data->fps << "\n";
    }
    if (!f) Fail(absl::InternalError("--csv: cannot write " + csv));
  }
  if (!lm_path.empty()) {
    std::ofstream f(lm_path);
    f << "method,threshold,from_clip,to_clip,lm_frames,response_frames\n";
    const size_t nclips = data->library->clips.size();
    for (const auto& r : rows) {
      for (size_t a = 0; a < nclips; ++a) {
        for (size_t b = 0; b < nclips; ++b) {
          if (a == b) continue;
          f << r.method << "," << r.threshold << "," << data->library->clips[a].name << ","
            << data->library->clips[b].name << "," << r.maneuverability[a * nclips + b] << ","
            << r.response_matrix[a * nclips + b] << "\n";
        }
      }
    }
  }
  if (!png.empty()) DrawPlot(rows, data->fps, png);
}

std::shared_ptr<const loco::LocomotionGraph> BuildGraph(std::shared_ptr<const loco::LocomotionData> data,
                                                        const std::string& profile, double threshold) {
  auto sp = OrFail(loco::BuiltinProfile(profile));
  loco::GraphParams params;
  params.threshold = threshold;
  return OrFail(loco::LocomotionGraph::Build(data, sp, params));
}

void RunPlan(const std::vector<std::string>& clips, const std::string& from, int frame, const std::string& to,
             const std::string& profile, double threshold, const std::string& out) {
  auto data = LoadData(clips, true);
  auto graph = BuildGraph(data, profile, threshold);
  const int fc = data->ClipIndex(from), tc = data->ClipIndex(to);
  if (fc < 0) Fail(InvalidField("--from", "no clip '" + from + "'"));
  if (tc < 0) Fail(InvalidField("--to", "no clip '" + to + "'"));
  const int n = data->clip_begin[static_cast<size_t>(fc) + 1] - data->clip_begin[static_cast<size_t>(fc)];
  if (frame < 0 || frame >= n) Fail(InvalidField("--frame", "out of range"));
  loco::SearchWorkspace ws;
  loco::Transition tr;
  const auto t0 = std::chrono::steady_clock::now();
  const Status st = loco::PlanTransition(*graph, data->clip_begin[static_cast<size_t>(fc)] + frame, tc, &ws, &tr);
  const double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
  if (!st.ok()) Fail(st);
  nlohmann::json j = {{"tbf_frames", tr.total_frames},
                      {"response_frames", tr.response_frames},
                      {"cost", loco::TransitionCost(*graph, tr)},
                      {"search_us", us},
                      {"frame_rate_hz", data->fps}};
  for (size_t p = 0; p < tr.parts.size(); ++p) {
    nlohmann::json chains = nlohmann::json::array();
    for (auto c : graph->parts()[p].chains) chains.push_back(std::string(loco::ChainName(c)));
    j["parts"].push_back({{"chains", chains},
                          {"origin_frame", data->FrameInClip(tr.parts[p].origin)},
                          {"target_frame", data->FrameInClip(tr.parts[p].target)},
                          {"start_offset_frames", tr.parts[p].start},
                          {"length_frames", tr.parts[p].length},
                          {"cost", tr.parts[p].cost}});
  }
  std::cout << j.dump(1) << "\n";
  if (!out.empty()) {
    auto clip = OrFail(loco::TransitionMotion(*graph, tr));
    const Status ws_status = motion::WriteBvhFile(clip, out, {.significant_digits = 9});
    if (!ws_status.ok()) Fail(ws_status);
  }
}

Eigen::Vector2d ParsePoint(const std::string& s, const char* field) {
  const auto parts = Split(s, ',');
  if (parts.size() != 2) Fail(InvalidField(field, "expected X,Y in metres"));
  try {
    return {std::stod(parts[0]), std::stod(parts[1])};
  } catch (...) {
    Fail(InvalidField(field, "expected X,Y in metres"));
  }
}

void RunDrive(const std::vector<std::string>& clips, const std::string& idle, const std::string& walk,
              const std::string& run, double speed, double cube_angle, const std::string& target,
              const std::string& path, double seconds, const std::string& profile, double threshold,
              const std::string& out, bool json) {
  auto data = LoadData(clips, true);
  auto graph = BuildGraph(data, profile, threshold);
  loco::DriveParams params;
  params.idle_clip = idle;
  params.walk_clip = walk;
  params.run_clip = run;
  auto drv = OrFail(loco::AvatarDriver::Create(graph, params));
  const double s = std::isfinite(cube_angle) ? loco::CubeAngleToSpeed(cube_angle) : speed;
  if (const Status st = drv->SetSpeed(s); !st.ok()) Fail(st);
  if (!target.empty()) drv->SetTarget(ParsePoint(target, "--target"));
  if (!path.empty()) {
    std::vector<Eigen::Vector2d> pts;
    for (const auto& p : Split(path, ';')) pts.push_back(ParsePoint(p, "--path"));
    if (const Status st = drv->SetPath(pts, true); !st.ok()) Fail(st);
  }
  const int frames = static_cast<int>(std::lround(seconds * data->fps));
  motion::Clip clip;
  clip.skeleton = data->library->skeleton;
  clip.frame_time_s = 1.0 / data->fps;
  clip.frames.resize(frames, clip.skeleton.num_channels());
  double reached_s = -1, min_dist = 1e9, max_speed = 0;
  nlohmann::json states = nlohmann::json::array();
  int last_state = -1;
  for (int f = 0; f < frames; ++f) {
    drv->Step(std::span<double>(clip.frames.data() + static_cast<Eigen::Index>(f) * clip.frames.cols(),
                                static_cast<size_t>(clip.frames.cols())));
    const auto& st = drv->status();
    if (st.target_reached && reached_s < 0) reached_s = st.time_s;
    if (!target.empty()) min_dist = std::min(min_dist, st.distance_to_target_m);
    max_speed = std::max(max_speed, st.speed_mps);
    if (static_cast<int>(st.state) != last_state) {
      last_state = static_cast<int>(st.state);
      static const char* names[] = {"idle", "walk", "run", "transition"};
      states.push_back({{"time_s", st.time_s}, {"state", names[last_state]}});
    }
  }
  const auto& st = drv->status();
  nlohmann::json j = {{"speed", s},
                      {"final_position_m", {st.root.position_m.x(), st.root.position_m.y()}},
                      {"final_distance_to_target_m", target.empty() ? nlohmann::json(nullptr)
                                                                    : nlohmann::json((ParsePoint(target, "--target") - st.root.position_m).norm())},
                      {"target_reached_s", reached_s >= 0 ? nlohmann::json(reached_s) : nlohmann::json(nullptr)},
                      {"max_ground_speed_mps", max_speed},
                      {"transitions", drv->transitions().size()},
                      {"states", states}};
  std::cout << j.dump(json ? 1 : -1) << "\n";
  if (!out.empty()) {
    const Status ws_status = motion::WriteBvhFile(clip, out, {.significant_digits = 9});
    if (!ws_status.ok()) Fail(ws_status);
  }
}

}  // namespace cmd_locomotion
}  // namespace

void RegisterLocomotionCommands(CLI::App& app) {
  using namespace cmd_locomotion;
  auto* loc = app.add_subcommand("locomotion", "Body Part Motion Graphs: evaluate, plan, drive (thesis ch. 3, §5.2)");
  loc->require_subcommand(1);

  struct EvalArgs {
    std::vector<std::string> clips;
    bool json = false;
    std::string profiles, thresholds, csv, png, lm;
    int stride = 1, threads = 0;
  };
  auto ea = std::make_shared<EvalArgs>();
  auto* ev = loc->add_subcommand("evaluate", "threshold sweep per split profile: connectivity, TBF, response, cost");
  ev->add_option("--clips", ea->clips, "BVH files or folders of locomotion clips")->required();
  ev->add_flag("--json", ea->json, "print the rows as JSON");
  ev->add_option("--profiles", ea->profiles, "comma-separated (default: SMG,SP2,SP3a,SP3b,SP4a,SP4b,SP5)");
  ev->add_option("--thresholds", ea->thresholds, "A:B:STEP or T,T,... (default 0.05:0.5:0.025)");
  ev->add_option("--stride", ea->stride, "every n-th frame is a request frame (default 1)");
  ev->add_option("--threads", ea->threads, "threads (default 0 = one per core; the rows do not depend on it)");
  ev->add_option("--csv", ea->csv, "write the rows as CSV");
  ev->add_option("--png", ea->png, "plot connectivity, TBF, response and cost vs threshold");
  ev->add_option("--lm", ea->lm, "write the clip-to-clip LM and response matrices as CSV");
  ev->add_option("--max-transitions", g_max_transitions, "keep the cheapest n transitions per frame and part (0 = all)");
  ev->callback([ea]() {
    RunEvaluate(ea->clips, ea->json, ea->profiles, ea->thresholds, ea->stride, ea->threads, ea->csv, ea->png, ea->lm);
  });

  struct PlanArgs {
    std::vector<std::string> clips;
    std::string from, to, profile = "SP5", out;
    int frame = 0;
    double threshold = 0.105;
  };
  auto pa = std::make_shared<PlanArgs>();
  auto* pl = loc->add_subcommand("plan", "one transition: metrics (JSON) and motion (BVH)");
  pl->add_option("--clips", pa->clips, "BVH files or folders")->required();
  pl->add_option("--from", pa->from, "clip playing")->required();
  pl->add_option("--frame", pa->frame, "request frame in that clip")->required();
  pl->add_option("--to", pa->to, "clip to reach")->required();
  pl->add_option("--profile", pa->profile, "split profile (default SP5)");
  pl->add_option("--threshold", pa->threshold, "global threshold (default 0.105)");
  pl->add_option("-o,--out", pa->out, "write the transition as BVH");
  pl->callback([pa]() { RunPlan(pa->clips, pa->from, pa->frame, pa->to, pa->profile, pa->threshold, pa->out); });

  struct DriveArgs {
    std::vector<std::string> clips;
    std::string idle, walk, run, target, path, profile = "SP5", out;
    double speed = 2.0, cube_angle = std::nan(""), seconds = 10, threshold = 0.105;
    bool json = false;
  };
  auto da = std::make_shared<DriveArgs>();
  auto* dr = loc->add_subcommand("drive", "the AvatAR offline: walk to a target or along a path");
  dr->add_option("--clips", da->clips, "BVH files or folders")->required();
  dr->add_option("--idle", da->idle, "idle clip")->required();
  dr->add_option("--walk", da->walk, "walk clip")->required();
  dr->add_option("--run", da->run, "run clip (default: the walk clip at run speeds)");
  dr->add_option("--speed", da->speed, "'Speed' (0 idle, walk from 0.5, run from 3.5; default 2)");
  dr->add_option("--cube-angle", da->cube_angle, "cube angle in degrees (thesis §5.2 mapping to Speed)");
  dr->add_option("--target", da->target, "X,Y in metres");
  dr->add_option("--path", da->path, "X,Y;X,Y;... followed in a loop");
  dr->add_option("--seconds", da->seconds, "length (default 10)");
  dr->add_option("--profile", da->profile, "split profile (default SP5)");
  dr->add_option("--threshold", da->threshold, "global threshold (default 0.105)");
  dr->add_option("-o,--out", da->out, "write the motion as BVH");
  dr->add_flag("--json", da->json, "indented JSON");
  dr->callback([da]() {
    RunDrive(da->clips, da->idle, da->walk, da->run, da->speed, da->cube_angle, da->target, da->path, da->seconds,
             da->profile, da->threshold, da->out, da->json);
  });
}

}  // namespace kinemo::cli
