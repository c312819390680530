// `kinemo prosody FILE [--json|--csv|--textgrid] [--keywords a,b,c] [--recognize] [--threads N]`
//
// Pitch, intensity, syllables, pitch accents (PAPT, strength, PSI) and
// pauses of a recording; with the recognizer (built with KINEMO_WITH_SPHINX)
// words and timed phones, or only spotted keywords with --keywords.
// --json prints one JSON object: frames [{time_s, f0_hz, voiced,
// intensity_db, ...}] at a 10 ms hop, syllables, accents, pauses, words,
// phones (with --recognize, recognizer_rtf: the recognizer's CPU seconds per
// second of audio). --threads N splits the analysis over N threads (default
// 0 = one per core; the results do not depend on it). Exit codes: 0 ok, 2 bad
// input or usage, 1 other failures.
#include <cstdio>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "common/audio/decode.h"
#include "services/cli/commands.h"
#include "services/prosody/core/pipeline.h"
#ifdef KINEMO_WITH_SPHINX
#include "services/prosody/core/recognizer.h"
#endif

namespace kinemo::cli {
namespace {
namespace cmd_prosody {  // this file's own helpers (the unity build puts files together)

struct ProsodyArgs {
  std::string file;
  bool json = false;
  bool csv = false;
  bool textgrid = false;
  bool recognize = false;
  std::string keywords;
  double keyword_threshold = 0;
  int analysis_rate_hz = 16000;
  double pitch_floor_hz = 75;
  double pitch_ceiling_hz = 600;
  double accent_threshold = 0.3;
  double min_accent_distance_s = 0.3;
  int threads = 0;
};

[[noreturn]] void Fail(const absl::Status& status) {
  FailCommand("prosody", status, {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound,
                                  absl::StatusCode::kPermissionDenied, absl::StatusCode::kFailedPrecondition});
}

void Run(const ProsodyArgs& args) {
  auto decoded = audio::DecodeAudioFile(args.file);
  if (!decoded.ok()) Fail(decoded.status());
  prosody::PipelineRequest request;
  request.analysis_rate_hz = args.analysis_rate_hz;
  request.options.pitch.floor_hz = args.pitch_floor_hz;
  request.options.pitch.ceiling_hz = args.pitch_ceiling_hz;
  request.options.accent.threshold = args.accent_threshold;
  request.options.accent.min_distance_s = args.min_accent_distance_s;
  request.options.threads = args.threads;
  request.recognize = args.recognize;
  request.keywords = SplitList(args.keywords, /*lower=*/true);
  request.keyword_threshold = args.keyword_threshold;
  const bool want_recognizer = request.recognize || !request.keywords.empty();
  prosody::SphinxRecognizer* recognizer = nullptr;
#ifdef KINEMO_WITH_SPHINX
  std::unique_ptr<prosody::SphinxRecognizer> owned;
  if (want_recognizer) {
    auto created = prosody::SphinxRecognizer::Create({});
    if (!created.ok()) Fail(created.status());
    owned = *std::move(created);
    recognizer = owned.get();
  }
#else
  (void)want_recognizer;
#endif
  auto result =
      prosody::RunPipeline(decoded->samples, decoded->sample_rate_hz, request, recognizer);
  if (!result.ok()) Fail(result.status());
  if (args.csv) {
    std::cout << prosody::ToCsv(*result);
  } else if (args.textgrid) {
    std::cout << prosody::ToTextGrid(*result);
  } else if (args.json) {
    std::cout << prosody::ToJson(*result, args.threads) << "\n";
  } else {
    const prosody::ProsodyResult& r = result->prosody;
    int voiced = 0;
    for (const auto& f : r.frames) voiced += f.voiced;
    std::printf("%s: %.2f s, %zu frames (%d voiced), %zu syllables, %zu accents, %zu pauses\n",
                args.file.c_str(), r.duration_s, r.frames.size(), voiced, r.syllables.size(),
                r.accents.size(), r.pauses.size());
    for (const auto& a : r.accents) {
      std::printf("  accent at %.3f s  strength %.2f  psi %.3f%s\n", a.time_s, a.strength, a.psi,
                  a.before_pause ? "  (before pause)" : "");
    }
    for (const auto& w : result->words) {
      std::printf("  word %-16s %.2f-%.2f s%s\n", w.word.c_str(), w.start_s, w.end_s,
                  w.keyword ? "  (keyword)" : "");
    }
  }
}

}  // namespace cmd_prosody
}  // namespace

void RegisterProsodyCommands(CLI::App& app) {
  using namespace cmd_prosody;
  auto args = std::make_shared<ProsodyArgs>();
  CLI::App* cmd = app.add_subcommand(
      "prosody", "Pitch, intensity, syllables, pitch accents, pauses (and words/phones) of FILE");
  cmd->add_option("FILE", args->file, "Audio file (WAV, FLAC, ...)")->required();
  auto* json = cmd->add_flag("--json", args->json, "One JSON object (frames, syllables, accents, "
                                                    "pauses, words, phones)");
  auto* csv = cmd->add_flag("--csv", args->csv, "One CSV row per 10 ms frame");
  auto* tg = cmd->add_flag("--textgrid", args->textgrid,
                           "Praat TextGrid (syllables, accents, pauses, words, phones)");
  json->excludes(csv)->excludes(tg);
  csv->excludes(tg);
  cmd->add_flag("--recognize", args->recognize, "Run the speech recognizer: words and timed phones");
  cmd->add_option("--keywords", args->keywords,
                  "Comma-separated keywords to spot; `words` then holds only them");
  cmd->add_option("--keyword-threshold", args->keyword_threshold,
                  "Sphinx -kws_threshold (default 1e-10)");
  cmd->add_option("--analysis-rate", args->analysis_rate_hz,
                  "Resample to this rate before analysis (0 = keep the file's rate)")
      ->capture_default_str();
  cmd->add_option("--pitch-floor", args->pitch_floor_hz, "Lowest F0 in Hz")->capture_default_str();
  cmd->add_option("--pitch-ceiling", args->pitch_ceiling_hz, "Highest F0 in Hz")
      ->capture_default_str();
  cmd->add_option("--accent-threshold", args->accent_threshold,
                  "Accent strength-indicator threshold, share of the maximum")
      ->capture_default_str();
  cmd->add_option("--min-accent-distance", args->min_accent_distance_s,
                  "Minimum time between accents in seconds")
      ->capture_default_str();
  cmd->add_option("--threads", args->threads,
                  "Threads for the analysis (0 = one per core; the results are the same)")
      ->capture_default_str();
  cmd->callback([args] { Run(*args); });
}

}  // namespace kinemo::cli
