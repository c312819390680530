// kinemo bench tones — the cube sets the tone of the talking character
// (issue 24), measured on an embedded kinemo_allinone (the bundled controller
// and its tones from styled capture, in a fresh store of its own) with its
// cube tracker:
//   1. latency: a rendered cube video (tests/data/cube/tone_scenario.json,
//      kinemo-vision cube render) plays in real time into a cube session
//      while speech streams in real time through StreamAnimate in that
//      session, --runs times; per cube change, the client's wall clock when
//      the tone_change arrives (with the first frames made in the tone) minus
//      when the tracker's event reached the coordinator; p50 / p95 / max,
//      and the live lag (motion lag p99, longest frame gap) of those streams;
//   2. per tone, on the same speech (--speech, default the bundled LibriVox
//      recordings back to back, never seen by the bundled model): mean and
//      p95 hand speed, gesture amplitude, and the Hellinger distance of the
//      hand-speed histogram to neutral (common/evaluation);
//   3. per tone and gesture emphasis (--emphases, planner.v1.StyleVector
//      .gesture_emphasis), on the same speech: mean hand speed and the
//      Hellinger distance of the hand-speed histogram to the same tone at
//      emphasis 0.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>

#include "common/audio/decode.h"
#include "common/process/process.h"
#include "nlohmann/json.hpp"
#include "services/cli/channel.h"
#include "services/cli/commands.h"
#include "services/cli/embedded_stack.h"
#include "bench/system/tone_motion.h"
#include "services/coordinator/client/cube_session.h"
#include "services/coordinator/client/live_client.h"

namespace kinemo::cli {
namespace {
namespace cmd_bench_tones {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;
namespace co = ::kinemo::coordinator;

struct ToneBenchArgs {
  int runs = 5;
  std::vector<std::string> speech, tones = {"neutral", "energetic", "angry", "happy", "subdued"};
  std::vector<double> emphases = {-1, -0.5, 0, 0.5, 1};
  std::string script, cube_model, controller = "bundled", model = "bundled";
  bool json = false;
};

[[noreturn]] void Fail(const Status& s) { FailCommand("bench tones", s, {absl::StatusCode::kInvalidArgument}); }

std::vector<float> Speech(const std::vector<std::string>& files, int* rate_hz) {
  std::vector<float> out;
  for (const auto& f : files) {
    auto a = audio::DecodeAudioFile(f);
    if (!a.ok()) Fail(Annotate(a.status(), "--speech"));
    if (*rate_hz != 0 && a->sample_rate_hz != *rate_hz) Fail(InvalidField("--speech", f, ": another sample rate"));
    *rate_hz = a->sample_rate_hz;
    out.insert(out.end(), a->samples.begin(), a->samples.end());
  }
  return out;
}

void Run(const ToneBenchArgs& a) {
  const std::string data = KINEMO_CLI_TEST_DATA_DIR;
  std::vector<std::string> speech_files = a.speech;
  if (speech_files.empty()) {
    for (const auto& e : fs::directory_iterator(data + "/speech"))
      if (e.path().extension() == ".wav") speech_files.push_back(e.path().string());
    std::sort(speech_files.begin(), speech_files.end());
  }
  int rate = 0;
  const std::vector<float> speech = Speech(speech_files, &rate);
  process::TempDir dir;
  // The cube video, rendered by kinemo-vision.
  const std::string vision = FindKinemoBinary("kinemo-vision", "cli");
  if (vision.empty()) {
    Fail(absl::NotFoundError("kinemo-vision: not found beside kinemo-bench, in the build tree or on PATH"));
  }
  const std::string video = dir.File("cube.avi"), camera = dir.File("cube.avi.camera.yaml");
  std::string out;
  auto rc = process::ChildProcess::Run({vision, "cube", "render", "--model", a.cube_model, "--script", a.script, "--out",
                                        video, "--truth", dir.File("truth.json"), "--camera", camera},
                                       dir.File("render.log"), std::chrono::minutes(5), &out);
  if (!rc.ok() || *rc != 0) Fail(absl::InternalError("kinemo-vision cube render failed (see --script)"));
  // The stack, whose cube tracker may read the video, on a store of its own
  // seeded from this build's bundled store: the home store's "bundled" may
  // come from an older kinemo (without tones or emphasis tables).
  const std::string config = dir.File("allinone.textproto");
  std::ofstream(config) << DefaultAllInOneConfig("bench tones") << "cube_tracker { file_root: \"" << dir.path()
                        << "\" }\nstore_dir: \"" << dir.File("store") << "\"\n";
  EmbeddedStack stack;
  const std::string address = stack.Start("bench tones", config, 120.0);
  if (address.empty()) throw CliExit{1};
  const auto channel = LocalChannel(address);

  // 1. Cube -> tone latency and the live lag while the cube runs.
  std::vector<double> latencies, lag_p99, gaps;
  int changes = 0, expected = 0;
  for (int run = 0; run < a.runs; ++run) {
    co::CubeSessionOptions so;
    so.video = video;
    so.camera = camera;
    so.cube_model_file = a.cube_model;
    auto session = co::OpenCubeSession(channel, so);
    if (!session.ok()) Fail(session.status());
    co::LiveStreamOptions o;
    o.realtime = true;
    o.config.mutable_models()->set_inference_model_id(a.model);
    o.config.mutable_models()->set_controller_id(a.controller);
    o.config.set_session_id(*session);
    o.config.set_request_id(kinemo::StrCat("bench-tones-", run));
    auto r = co::RunLiveStream(channel, speech, rate, o);
    (void)co::CloseCubeSession(channel, *session);
    if (!r.ok()) Fail(r.status());
    expected += 2;  // kisses, shouting
    for (const auto& t : r->tone_changes) {
      if (t.change.initial() || t.change.superseded()) continue;
      latencies.push_back(t.latency_ms);
      ++changes;
    }
    lag_p99.push_back(r->motion_lag_p99_ms);
    gaps.push_back(r->max_frame_gap_ms);
    if (!a.json)
      std::fprintf(stderr, "run %d: %zu tone changes, motion lag p99 %.1f ms, longest gap %.1f ms\n", run + 1,
                   r->tone_changes.size(), r->motion_lag_p99_ms, r->max_frame_gap_ms);
  }
  // 2. Per tone, the same speech, no cube; 3. per tone and emphasis.
  auto animate = [&](const std::string& tone, double emphasis) {
    co::LiveStreamOptions o;
    o.realtime = false;
    o.config.mutable_models()->set_inference_model_id(a.model);
    o.config.mutable_models()->set_controller_id(a.controller);
    (*o.config.mutable_style()->mutable_tone_weights())[tone] = 1.0;
    o.config.mutable_style()->set_gesture_emphasis(emphasis);
    auto r = co::RunLiveStream(channel, speech, rate, o);
    if (!r.ok()) Fail(Annotate(r.status(), kinemo::StrCat(tone, " emphasis ", emphasis)));
    auto clip = co::ClipFromStream(r->header, r->frames);
    if (!clip.ok()) Fail(clip.status());
    return *std::move(clip);
  };
  std::map<std::string, co::ToneMotion> per_tone;
  std::map<std::string, std::map<double, co::ToneMotion>> per_emphasis;  // tone -> e -> vs the tone at e = 0
  std::optional<motion::Clip> neutral;
  for (const auto& tone : a.tones) {
    const motion::Clip clip = animate(tone, 0);
    if (!neutral) neutral = clip;
    auto m = co::MeasureToneMotion(clip, &*neutral);
    if (!m.ok()) Fail(m.status());
    per_tone[tone] = *m;
    for (double e : a.emphases) {
      auto me = e == 0 ? co::MeasureToneMotion(clip, &clip) : co::MeasureToneMotion(animate(tone, e), &clip);
      if (!me.ok()) Fail(me.status());
      per_emphasis[tone][e] = *me;
    }
  }
  const double p50 = co::Percentile(latencies, 0.5), p95 = co::Percentile(latencies, 0.95);
  const double lmax = latencies.empty() ? 0 : *std::max_element(latencies.begin(), latencies.end());
  const double lag = lag_p99.empty() ? 0 : *std::max_element(lag_p99.begin(), lag_p99.end());
  const double gap = gaps.empty() ? 0 : *std::max_element(gaps.begin(), gaps.end());
  const co::ToneMotion& n = per_tone[a.tones.front()];
  if (a.json) {
    nlohmann::json tones = nlohmann::json::array();
    for (const auto& t : a.tones) {
      const auto& m = per_tone[t];
      tones.push_back({{"tone", t}, {"hand_speed_mean_m_s", m.hand_speed_mean_m_s},
                       {"hand_speed_p95_m_s", m.hand_speed_p95_m_s}, {"amplitude_m", m.amplitude_m},
                       {"hellinger_speed_to_neutral", m.hellinger_speed_to_neutral}});
    }
    nlohmann::json emphasis = nlohmann::json::array();
    for (const auto& t : a.tones)
      for (double e : a.emphases) {
        const auto& m = per_emphasis[t][e];
        emphasis.push_back({{"tone", t}, {"gesture_emphasis", e}, {"hand_speed_mean_m_s", m.hand_speed_mean_m_s},
                            {"amplitude_m", m.amplitude_m}, {"hellinger_speed_to_emphasis_0", m.hellinger_speed_to_neutral}});
      }
    const nlohmann::json j = {{"runs", a.runs}, {"changes", changes}, {"expected_changes", expected},
                              {"tone_latency_p50_ms", p50}, {"tone_latency_p95_ms", p95},
                              {"tone_latency_max_ms", lmax}, {"motion_lag_p99_ms_max", lag},
                              {"max_frame_gap_ms", gap}, {"speech_s", static_cast<double>(speech.size()) / rate},
                              {"tones", tones}, {"emphasis", emphasis}};
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("cube face change -> first frame in the new tone (%d runs, %d of %d changes arrived)\n", a.runs,
              changes, expected);
  std::printf("| p50 | p95 | max | target p95 | live lag p99 (worst run) | longest frame gap |\n");
  std::printf("|---|---|---|---|---|---|\n");
  std::printf("| %.0f ms | %.0f ms | %.0f ms | 300 ms | %.1f ms | %.1f ms |\n\n", p50, p95, lmax, lag, gap);
  std::printf("per tone, %.1f s of speech (%zu recordings)\n", static_cast<double>(speech.size()) / rate,
              speech_files.size());
  std::printf("| tone | hand speed mean | x neutral | p95 | amplitude | x neutral | hand-speed Hellinger to neutral |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  for (const auto& t : a.tones) {
    const auto& m = per_tone[t];
    std::printf("| %s | %.3f m/s | %.2f | %.3f m/s | %.3f m | %.2f | %.3f |\n", t.c_str(), m.hand_speed_mean_m_s,
                m.hand_speed_mean_m_s / n.hand_speed_mean_m_s, m.hand_speed_p95_m_s, m.amplitude_m,
                m.amplitude_m / n.amplitude_m, m.hellinger_speed_to_neutral);
  }
  std::printf("\nper tone and gesture emphasis e: mean hand speed (x the tone at e = 0) / hand-speed Hellinger to e = 0\n");
  std::printf("| tone |");
  for (double e : a.emphases) std::printf(" e = %+.1f |", e);
  std::printf("\n|---|");
  for (size_t k = 0; k < a.emphases.size(); ++k) std::printf("---|");
  std::printf("\n");
  for (const auto& t : a.tones) {
    const double v0 = per_tone[t].hand_speed_mean_m_s;
    std::printf("| %s |", t.c_str());
    for (double e : a.emphases) {
      const auto& m = per_emphasis[t][e];
      std::printf(" %.3f m/s (%.2f) / %.3f |", m.hand_speed_mean_m_s, m.hand_speed_mean_m_s / v0,
                  m.hellinger_speed_to_neutral);
    }
    std::printf("\n");
  }
}

}  // namespace cmd_bench_tones
}  // namespace

void RegisterToneBenchCommands(CLI::App& app) {
  using namespace cmd_bench_tones;
  CLI::App* bench = SharedSubcommand(app, "bench", "Benchmarks of the whole system");
  auto* cmd = bench->add_subcommand(
      "tones", "The cube sets the tone: face change -> first frame in the tone, live lag, per-tone hand speed");
  auto a = std::make_shared<ToneBenchArgs>();
  a->script = std::string(KINEMO_CLI_TEST_DATA_DIR) + "/cube/tone_scenario.json";
  a->cube_model = std::string(KINEMO_CLI_TEST_DATA_DIR) + "/cube/vleo.cube";
  cmd->add_option("--runs", a->runs, "real-time runs of the cube video and the speech")->capture_default_str();
  cmd->add_option("--speech", a->speech, "recordings, streamed back to back (default: tests/data/speech/*.wav)");
  cmd->add_option("--tones", a->tones, "tones of the per-tone table, the first the reference")->delimiter(',');
  cmd->add_option("--emphases", a->emphases, "gesture emphases of the per-emphasis table, each in [-1, 1]")
      ->delimiter(',');
  cmd->add_option("--script", a->script, "cube render script")->capture_default_str();
  cmd->add_option("--cube-model", a->cube_model, "cube model")->capture_default_str();
  cmd->add_option("--controller-id", a->controller, "controller id")->capture_default_str();
  cmd->add_option("--model-id", a->model, "inference model id")->capture_default_str();
  cmd->add_flag("--json", a->json, "one JSON object");
  cmd->callback([a] {
    if (a->runs < 1 || a->runs > 100) Fail(InvalidField("--runs", "must be in [1, 100]"));
    if (a->tones.empty()) Fail(InvalidField("--tones", "needs at least one"));
    if (a->emphases.size() > 9) Fail(InvalidField("--emphases", "at most 9"));
    for (double e : a->emphases)
      if (!(e >= -1 && e <= 1)) Fail(InvalidField("--emphases", e, " must be in [-1, 1]"));
    Run(*a);
  });
}

}  // namespace kinemo::cli
