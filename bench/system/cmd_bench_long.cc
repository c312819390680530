// kinemo bench long — a long recording animated offline, as a user would:
// `kinemo animate LONG -o OUT.bvh --json` on an embedded kinemo_allinone,
// timed, with the peak memory of the whole stack (kinemo and its
// kinemo_allinone: the sum of their peak resident sizes) and the memory per
// minute of audio (above a short recording's run).
//
// The recording is made from the bundled speech (the two BEAT2 takes and the
// LibriVox clips of tests/data, 150 s), repeated with pauses of 0.3-2.5 s
// between the clips and a different gain each time, to the length asked, at
// the rate, channels and format asked (WAV, MP3, OGG, FLAC by libsndfile: no
// other tool), in a temporary folder that is removed afterwards (--keep DIR
// keeps it).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>

#include "common/audio/decode.h"
#include "common/audio/recording_writer.h"
#include "common/audio/resample.h"
#include "common/process/process.h"
#include "nlohmann/json.hpp"
#include "services/cli/commands.h"
#include "services/cli/embedded_stack.h"

namespace kinemo::cli {
namespace {
namespace cmd_bench_long {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;

struct LongArgs {
  double minutes = 10;
  std::string format = "wav", method = "bodyspeech", keep, allinone_config;
  int rate_hz = 44100, channels = 2;
  double timeout_s = 0;
  bool json = false, preview = false;
};

[[noreturn]] void Fail(const Status& s) {
  std::cerr << "kinemo bench long: " << s.message() << "\n";
  throw CliExit{absl::IsInvalidArgument(s) || absl::IsNotFound(s) ? 2 : 1};
}

// The bundled speech at `rate_hz`, one vector per clip.
std::vector<std::vector<float>> BundledSpeech(int rate_hz) {
  const std::string data = KINEMO_CLI_TEST_DATA_DIR;
  std::vector<std::string> files;
  for (const std::string& dir : {data + "/paired/beat2", data + "/speech"}) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      if (e.path().extension() == ".wav") files.push_back(e.path().string());
    }
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) Fail(absl::NotFoundError(kinemo::StrCat(data, ": no bundled speech (paired/beat2, speech)")));
  std::vector<std::vector<float>> clips;
  for (const auto& f : files) {
    auto a = audio::DecodeAudioFile(f);
    if (!a.ok()) Fail(a.status());
    auto r = audio::Resample(a->samples, a->sample_rate_hz, rate_hz);
    if (!r.ok()) Fail(r.status());
    clips.push_back(*std::move(r));
  }
  return clips;
}

// Writes `seconds` of the clips with pauses to `path`.
void MakeRecording(const std::string& path, double seconds, const LongArgs& a,
                   const std::vector<std::vector<float>>& clips) {
  auto w = audio::RecordingWriter::Create(path, a.rate_hz, a.channels);
  if (!w.ok()) Fail(w.status());
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> pause_s(0.3, 2.5), gain(0.6, 1.0);
  const auto total = static_cast<std::int64_t>(std::llround(seconds * a.rate_hz));
  std::int64_t written = 0;
  std::vector<float> block;
  auto put = [&](const float* mono, std::int64_t n, double g) {
    n = std::min(n, total - written);
    block.resize(static_cast<std::size_t>(n * a.channels));
    for (std::int64_t i = 0; i < n; ++i) {
      const float x = mono == nullptr ? 0.0f : static_cast<float>(mono[i] * g);
      // The second channel a little quieter: a stereo file, not two copies.
      for (int c = 0; c < a.channels; ++c) block[static_cast<std::size_t>(i * a.channels + c)] = c == 0 ? x : 0.9f * x;
    }
    if (Status s = (*w)->Write(block); !s.ok()) Fail(s);
    written += n;
  };
  for (std::size_t k = 0; written < total; ++k) {
    const auto& clip = clips[k % clips.size()];
    put(clip.data(), static_cast<std::int64_t>(clip.size()), gain(rng));
    const auto pause = static_cast<std::int64_t>(pause_s(rng) * a.rate_hz);
    for (std::int64_t done = 0; done < pause && written < total; done += a.rate_hz) {
      put(nullptr, std::min<std::int64_t>(a.rate_hz, pause - done), 1.0);
    }
  }
  if (Status s = (*w)->Close(); !s.ok()) Fail(s);
}

// `kinemo animate FILE -o OUT --json`: its JSON line and wall time.
nlohmann::json Animate(const std::string& kinemo, const std::string& file, const std::string& out,
                       const LongArgs& a, const std::string& config, const std::string& log, double* wall_s) {
  std::vector<std::string> argv = {kinemo, "animate", file, "-o", out, "--json", "--embedded",
                                   "--allinone-config", config, "--method", a.method};
  if (a.timeout_s > 0) {
    argv.push_back("--timeout-s");
    argv.push_back(kinemo::StrCat(a.timeout_s));
  }
  std::string output;
  const auto t0 = std::chrono::steady_clock::now();
  auto rc = process::ChildProcess::Run(argv, log, std::chrono::hours(4), &output);
  *wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!rc.ok()) Fail(rc.status());
  if (*rc != 0) {
    std::cerr << output;
    Fail(absl::InternalError(kinemo::StrCat("kinemo animate ", file, " exited ", *rc)));
  }
  // The last JSON line (progress lines go to stderr, in the same log).
  std::string line, last;
  std::istringstream in(output);
  while (std::getline(in, line)) {
    if (!line.empty() && line.front() == '{') last = line;
  }
  auto j = nlohmann::json::parse(last, nullptr, false);
  if (j.is_discarded() || !j.contains("peak_rss_mb")) {
    Fail(absl::InternalError(kinemo::StrCat("kinemo animate printed no summary: ", output)));
  }
  return j;
}

void Run(const LongArgs& a) {
  if (!(a.minutes > 0 && a.minutes <= 120)) Fail(InvalidField("--minutes", "must be in (0, 120], got ", a.minutes));
  if (a.format != "wav" && a.format != "mp3" && a.format != "ogg" && a.format != "flac") {
    Fail(InvalidField("--format", "'", a.format, "' is not wav, mp3, ogg or flac"));
  }
  const std::string kinemo = FindKinemoBinary("kinemo", "cli");
  if (kinemo.empty()) Fail(absl::NotFoundError("kinemo: not found beside kinemo-bench, in the build tree or on PATH"));
  process::TempDir tmp;
  const std::string dir = a.keep.empty() ? tmp.path() : a.keep;
  std::error_code ec;
  fs::create_directories(dir, ec);
  // A store of its own, seeded from this build's bundled store.
  std::string config = a.allinone_config;
  if (config.empty()) {
    config = (fs::path(dir) / "allinone.textproto").string();
    std::ofstream(config) << DefaultAllInOneConfig("bench long") << "store_dir: \"" << (fs::path(dir) / "store").string()
                          << "\"\n";
  }
  const auto clips = BundledSpeech(a.rate_hz);
  const std::string stem = kinemo::StrCat("long-", a.minutes, "min-", a.rate_hz, "hz-", a.channels, "ch");
  const std::string base_file = (fs::path(dir) / kinemo::StrCat("base.", a.format)).string();
  const std::string file = (fs::path(dir) / kinemo::StrCat(stem, ".", a.format)).string();
  const std::string out = (fs::path(dir) / kinemo::StrCat(stem, "-", a.method, ".bvh")).string();
  std::cerr << "kinemo bench long: making " << a.minutes << " min of " << a.format << " at " << a.rate_hz << " Hz, "
            << a.channels << " channel(s) in " << dir << "\n";
  MakeRecording(base_file, 30, a, clips);
  MakeRecording(file, a.minutes * 60, a, clips);
  // The stack's memory with a short recording (the libraries, models, ...),
  // then with the long one.
  double base_wall_s = 0, wall_s = 0;
  const nlohmann::json base = Animate(kinemo, base_file, (fs::path(dir) / "base.bvh").string(), a, config,
                                      (fs::path(dir) / "base.log").string(), &base_wall_s);
  const nlohmann::json run =
      Animate(kinemo, file, out, a, config, (fs::path(dir) / "animate.log").string(), &wall_s);
  const double peak = run["peak_rss_mb"].get<double>(), base_peak = base["peak_rss_mb"].get<double>();
  nlohmann::json j = {{"minutes", a.minutes},
                      {"seconds", wall_s},
                      {"peak_rss_mb", peak},
                      {"rss_mb_per_min", (peak - base_peak) / (a.minutes - 0.5)},
                      {"base_rss_mb", base_peak},
                      {"method", a.method},
                      {"format", a.format},
                      {"rate_hz", a.rate_hz},
                      {"channels", a.channels},
                      {"file_mb", static_cast<double>(fs::file_size(file, ec)) / (1 << 20)},
                      {"audio_s", run["audio_s"]},
                      {"frames", run["frames"]},
                      {"face_frames", run.value("face_frames", 0)},
                      {"bvh_mb", static_cast<double>(fs::file_size(out, ec)) / (1 << 20)},
                      {"stage_times_s", run.value("times", nlohmann::json::object())}};
  if (a.preview) {
    // The BVH plays: kinemo preview reads it whole and draws its frames.
    std::string output;
    const std::string png = (fs::path(dir) / kinemo::StrCat(stem, "-", a.method, ".png")).string();
    auto rc = process::ChildProcess::Run({kinemo, "preview", out, "-o", png}, (fs::path(dir) / "preview.log").string(),
                                         std::chrono::minutes(30), &output);
    j["preview_ok"] = rc.ok() && *rc == 0 && fs::file_size(png, ec) > 0;
  }
  if (a.json) {
    std::printf("%s\n", j.dump().c_str());
  } else {
    std::printf("%.1f min %s %d Hz %d ch, %s: %.1f s, peak RSS %.0f MB (%.0f MB for 30 s; %.1f MB per minute), "
                "%lld frames, BVH %.0f MB\n",
                a.minutes, a.format.c_str(), a.rate_hz, a.channels, a.method.c_str(), wall_s, peak, base_peak,
                j["rss_mb_per_min"].get<double>(), static_cast<long long>(run["frames"].get<std::int64_t>()),
                j["bvh_mb"].get<double>());
  }
}

}  // namespace cmd_bench_long
}  // namespace

void RegisterLongBenchCommands(CLI::App& app) {
  using namespace cmd_bench_long;
  CLI::App* bench = SharedSubcommand(app, "bench", "System benchmarks");
  auto* cmd = bench->add_subcommand(
      "long", "A long recording (made from the bundled speech) animated offline: time, peak memory, MB per minute");
  auto a = std::make_shared<LongArgs>();
  cmd->add_option("--minutes", a->minutes, "length of the recording, in minutes (up to 120)")->capture_default_str();
  cmd->add_option("--format", a->format, "wav | mp3 | ogg | flac")->capture_default_str();
  cmd->add_option("--rate", a->rate_hz, "sample rate of the recording, in Hz")->capture_default_str();
  cmd->add_option("--channels", a->channels, "channels of the recording")->capture_default_str();
  cmd->add_option("-m,--method", a->method, "gc | gmg | bodyspeech")->capture_default_str();
  cmd->add_option("--timeout-s", a->timeout_s, "kinemo animate's deadline (0 = its default)");
  cmd->add_option("--allinone-config", a->allinone_config,
                  "options of the embedded kinemo_allinone (default: the bundled ones, a store of its own)");
  cmd->add_option("--keep", a->keep, "make and keep the recording and the BVH in this folder");
  cmd->add_flag("--preview", a->preview, "also draw the BVH with kinemo preview (preview_ok)");
  cmd->add_flag("--json", a->json,
                "print {minutes, seconds, peak_rss_mb, rss_mb_per_min, base_rss_mb, method, format, rate_hz, "
                "channels, file_mb, audio_s, frames, face_frames, bvh_mb, stage_times_s}");
  cmd->callback([a] { Run(*a); });
}

}  // namespace kinemo::cli
