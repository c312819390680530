// Gesture Motion Graph and BodySpeech (thesis §4.4-4.5) from the command line.
//
//   kinemo gmg sweep --library DIR [--content LIST] [--thresholds 0.3,0.4,...] [--json]
//       Table 4.2: for each similarity threshold st, graph size, branching
//       factor, largest-SCC size and its branching factor. --json prints
//       [{st, size, bf, scc_size, scc_bf}].
//   kinemo gmg phrases --library DIR [--content LIST]
//       The automatic gesture phrases, as a manifest with each clip's
//       "phrases" annotation (correct it and load it with --library).
//   kinemo gestures FILE.wav --library DIR -o OUT.bvh [--visemes OUT.json|OUT.csv]
//       [--report REPORT.json] [--algorithm bodyspeech|gmg] [--accents FILE.json] [--no-plant-feet]
//       Runs the prosody analysis (pitch accents; timed phones with the
//       recognizer) and synthesises gestures for the speech: a continuous BVH,
//       viseme tracks and a report per accent {papt_s, apex_s, psi, gsi, warp,
//       edge, ...}; accents left without gesture carry `reason`.
//
// --library takes BVH files, folders or manifests (repeatable). In folders,
// Bandai-Namco clips (dataset-N_<content>_<style>_NNN.bvh) are filtered by
// --content: "gestures" (default: bow, bye, byebye, guide, respond, call),
// "all", or a comma-separated list of contents.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "common/audio/decode.h"
#include "common/motion/bvh.h"
#include "services/cli/commands.h"
#include "services/planner/gesture/graph.h"
#include "services/planner/gesture/phrases.h"
#include "services/planner/gesture/synthesis.h"
#include "services/planner/gesture/visemes.h"
#include "services/planner/library/library.h"
#include "services/prosody/core/pipeline.h"
#ifdef KINEMO_WITH_SPHINX
#include "services/prosody/core/recognizer.h"
#endif

namespace kinemo::cli {
namespace {
namespace cmd_gestures {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;
namespace gs = kinemo::planner::gesture;
using Json = nlohmann::json;

[[noreturn]] void Fail(std::string_view cmd, const absl::Status& status) {
  FailCommand(cmd, status, {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound,
                            absl::StatusCode::kFailedPrecondition, absl::StatusCode::kOutOfRange});
}

struct LibraryArgs {
  std::vector<std::string> library;
  std::string content = "gestures";
};

void AddLibraryOptions(CLI::App* cmd, LibraryArgs* a) {
  cmd->add_option("--library", a->library, "BVH files, folders or manifests of gesture clips")->required();
  cmd->add_option("--content", a->content,
                  "Bandai clips kept from folders: gestures (bow, bye, byebye, guide, respond, call), all, "
                  "or a comma-separated list")
      ->capture_default_str();
}

StatusOr<std::shared_ptr<planner::Library>> LoadGestureLibrary(const LibraryArgs& a) {
  std::set<std::string> keep;
  const bool all = a.content == "all";
  if (a.content == "gestures") {
    keep = {"bow", "bye", "byebye", "guide", "respond", "call"};
  } else if (!all) {
    for (auto& c : SplitList(a.content)) keep.insert(c);
  }
  planner::LibrarySources src;
  for (const auto& p : a.library) {
    std::error_code ec;
    if (fs::is_directory(p, ec)) {
      std::vector<std::string> files;
      for (const auto& e : fs::recursive_directory_iterator(p, ec)) {
        if (!e.is_regular_file() || e.path().extension() != ".bvh") continue;
        auto name = planner::ParseBandaiName(e.path().stem().string());
        if (!all && name && !keep.count(name->content)) continue;
        files.push_back(e.path().string());
      }
      std::sort(files.begin(), files.end());
      if (files.empty()) return InvalidField("--library", "no BVH clips kept in ", p);
      src.paths.insert(src.paths.end(), files.begin(), files.end());
    } else if (fs::exists(p, ec)) {
      src.paths.push_back(p);
    } else {
      return absl::NotFoundError(kinemo::StrCat("--library: no such file or folder: ", p));
    }
  }
  return planner::LoadLibrary("cli", src);
}

// ---- kinemo gmg sweep / phrases

struct SweepArgs {
  LibraryArgs lib;
  std::string thresholds = "0.3,0.4,0.5,0.6,0.7,0.8,0.9,1.0";
  bool json = false;
};

void RunSweep(const SweepArgs& a) {
  auto lib = LoadGestureLibrary(a.lib);
  if (!lib.ok()) Fail("gmg sweep", lib.status());
  auto set = gs::ExtractPhrases(**lib);
  if (!set.ok()) Fail("gmg sweep", set.status());
  std::vector<double> st;
  for (const auto& s : SplitList(a.thresholds)) {
    try {
      st.push_back(std::stod(s));
    } catch (...) {
      Fail("gmg sweep", InvalidField("--thresholds", "'", s, "' is not a number"));
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  auto rows = gs::GestureGraph::Sweep(**lib, *set, st, {});
  if (!rows.ok()) Fail("gmg sweep", rows.status());
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (a.json) {
    Json out = Json::array();
    for (const auto& r : *rows) {
      out.push_back({{"st", r.similarity_threshold},
                     {"size", r.size},
                     {"bf", r.branching_factor},
                     {"scc_size", r.scc_size},
                     {"scc_bf", r.scc_branching_factor}});
    }
    std::cout << out.dump() << "\n";
    return;
  }
  std::printf("%zu clips, %zu gesture phrases (sweep in %.3f s)\n", (*lib)->clips.size(), set->phrases.size(), secs);
  std::printf("%6s %6s %8s %9s %8s\n", "st", "size", "BF", "SCC size", "SCC BF");
  for (const auto& r : *rows) {
    std::printf("%6.2f %6d %8.2f %9d %8.2f\n", r.similarity_threshold, r.size, r.branching_factor, r.scc_size,
                r.scc_branching_factor);
  }
}

void RunPhrases(const LibraryArgs& a) {
  auto lib = LoadGestureLibrary(a);
  if (!lib.ok()) Fail("gmg phrases", lib.status());
  auto set = gs::ExtractPhrases(**lib);
  if (!set.ok()) Fail("gmg phrases", set.status());
  Json clips = Json::array();
  for (size_t c = 0; c < (*lib)->clips.size(); ++c) {
    const auto& lc = (*lib)->clips[c];
    clips.push_back({{"path", fs::absolute(lc.source).string()},
                     {"name", lc.name},
                     {"tone", lc.tone},
                     {"phrases", Json::parse(gs::PhrasesToAnnotationJson(**lib, *set, static_cast<int>(c)))}});
  }
  std::cout << Json{{"clips", clips}}.dump(1) << "\n";
}

// ---- kinemo gestures

struct GesturesArgs {
  std::string file;
  LibraryArgs lib;
  std::string out_bvh;
  std::string visemes;
  std::string report;
  std::string accents_file;
  std::string algorithm = "bodyspeech";
  double similarity_threshold = 1.0;
  double gesture_emphasis = 0;
  double face_emphasis = 0;
  double accent_threshold = 0.3;
  double min_accent_distance_s = 0.3;
  uint64_t seed = 0;
  bool no_recognize = false;
  bool no_stroke_phrases = false;
  bool no_plant_feet = false;
};

std::string EdgeKindName(gs::EdgeKind k) {
  switch (k) {
    case gs::EdgeKind::kConsecutive: return "E1";
    case gs::EdgeKind::kSimilarity: return "E2";
    case gs::EdgeKind::kRest: return "rest";
  }
  return "E2";
}

Status WriteText(const std::string& path, const std::string& text, std::string_view field) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  f.close();
  if (!f) return absl::PermissionDeniedError(kinemo::StrCat(field, ": cannot write ", path));
  return absl::OkStatus();
}

StatusOr<std::vector<gs::AccentInput>> ReadAccents(const std::string& path, std::vector<gs::VisemeAccent>* va) {
  std::ifstream f(path);
  if (!f) return absl::NotFoundError(kinemo::StrCat("--accents: cannot read ", path));
  Json j = Json::parse(f, nullptr, false);
  if (j.is_discarded()) return InvalidField("--accents", path, " is not JSON");
  if (j.is_object() && j.contains("accents")) j = j["accents"];
  if (!j.is_array()) return InvalidField("--accents", "needs an array of {time_s, strength, psi}");
  std::vector<gs::AccentInput> out;
  for (size_t i = 0; i < j.size(); ++i) {
    const Json& a = j[i];
    if (!a.is_object() || !(a.contains("time_s") || a.contains("papt_s"))) {
      return InvalidField(kinemo::StrCat("--accents[", i, "]"), "needs time_s");
    }
    gs::AccentInput in;
    in.papt_s = a.contains("time_s") ? a["time_s"].get<double>() : a["papt_s"].get<double>();
    in.strength = a.value("strength", 0.5);
    in.psi = a.value("psi", 0.0);
    out.push_back(in);
    va->push_back({in.papt_s, in.strength, a.value("syllable_start_s", 0.0), a.value("syllable_end_s", 0.0)});
  }
  return out;
}

void RunGestures(const GesturesArgs& a) {
  const char* cmd = "gestures";
  gs::Algorithm alg;
  if (a.algorithm == "bodyspeech") {
    alg = gs::Algorithm::kBodySpeech;
  } else if (a.algorithm == "gmg") {
    alg = gs::Algorithm::kGmg;
  } else {
    Fail(cmd, InvalidField("--algorithm", "must be bodyspeech or gmg"));
  }
  // Speech: accents and phones.
  auto decoded = audio::DecodeAudioFile(a.file);
  if (!decoded.ok()) Fail(cmd, decoded.status());
  const double duration_s =
      static_cast<double>(decoded->samples.size()) / static_cast<double>(decoded->sample_rate_hz);
  std::vector<gs::AccentInput> accents;
  std::vector<gs::VisemeAccent> vaccents;
  std::vector<gs::TimedPhone> phones;
  bool recognizer_ran = false;
  {
    prosody::PipelineRequest req;
    req.options.accent.threshold = a.accent_threshold;
    req.options.accent.min_distance_s = a.min_accent_distance_s;
    prosody::SphinxRecognizer* recognizer = nullptr;
#ifdef KINEMO_WITH_SPHINX
    std::unique_ptr<prosody::SphinxRecognizer> owned;
    if (!a.no_recognize && !a.visemes.empty()) {
      auto created = prosody::SphinxRecognizer::Create({});
      if (!created.ok()) Fail(cmd, created.status());
      owned = *std::move(created);
      recognizer = owned.get();
      req.recognize = true;
    }
#endif
    auto result = prosody::RunPipeline(decoded->samples, decoded->sample_rate_hz, req, recognizer);
    if (!result.ok()) Fail(cmd, result.status());
    recognizer_ran = result->recognizer_ran;
    for (const auto& p : result->phones) phones.push_back({p.phone, p.start_s, p.end_s});
    if (a.accents_file.empty()) {
      for (const auto& acc : result->prosody.accents) {
        accents.push_back({acc.time_s, acc.strength, acc.psi});
        vaccents.push_back({acc.time_s, acc.strength, acc.syllable_start_s, acc.syllable_end_s});
      }
    }
  }
  if (!a.accents_file.empty()) {
    auto read = ReadAccents(a.accents_file, &vaccents);
    if (!read.ok()) Fail(cmd, read.status());
    accents = *std::move(read);
  }
  // Motion.
  auto lib = LoadGestureLibrary(a.lib);
  if (!lib.ok()) Fail(cmd, lib.status());
  auto set = gs::ExtractPhrases(**lib);
  if (!set.ok()) Fail(cmd, set.status());
  gs::GraphParams gp;
  gp.similarity_threshold = a.similarity_threshold;
  gp.stroke_phrases = alg == gs::Algorithm::kBodySpeech && !a.no_stroke_phrases;
  auto graph = gs::GestureGraph::Build(*lib, *std::move(set), gp);
  if (!graph.ok()) Fail(cmd, graph.status());
  gs::SynthesisParams sp;
  sp.seed = a.seed;
  sp.gesture_emphasis = a.gesture_emphasis;
  sp.duration_s = duration_s;
  sp.feet.enabled = !a.no_plant_feet;
  auto synth = gs::Synthesize(**graph, accents, alg, sp);
  if (!synth.ok()) Fail(cmd, synth.status());
  if (auto st = motion::WriteBvhFile(synth->clip, a.out_bvh, {9, "\t"}); !st.ok()) Fail(cmd, st);
  if (!a.visemes.empty()) {
    gs::VisemeParams vp;
    vp.face_emphasis = a.face_emphasis;
    vp.duration_s = duration_s;
    vp.frame_time_s = synth->clip.frame_time_s;
    auto track = gs::ComputeVisemes(phones, vaccents, vp);
    if (!track.ok()) Fail(cmd, track.status());
    const bool csv = fs::path(a.visemes).extension() == ".csv";
    if (auto st = WriteText(a.visemes, csv ? gs::VisemesToCsv(*track) : gs::VisemesToJson(*track), "--visemes");
        !st.ok()) {
      Fail(cmd, st);
    }
  }
  const auto& g = **graph;
  if (!a.report.empty()) {
    Json rows = Json::array();
    for (const auto& p : synth->report) {
      Json r{{"accent_index", p.accent_index}, {"papt_s", p.papt_s}, {"psi", p.psi}, {"placed", p.placed}};
      if (p.placed) {
        const auto& ph = g.phrases()[static_cast<size_t>(p.phrase)];
        r["apex_s"] = p.apex_s;
        r["gsi"] = p.gsi;
        r["warp"] = p.warp;
        r["edge"] = {{"kind", EdgeKindName(p.edge_kind)},
                     {"from", p.from_node == g.rest_node() ? Json("rest") : Json(p.from_node)},
                     {"to", p.to_node},
                     {"weight", p.edge_weight},
                     {"blend_s", p.edge_blend_s}};
        r["phrase"] = p.phrase;
        r["clip"] = g.library().clips[static_cast<size_t>(ph.clip)].name;
        r["anticipation_s"] = p.anticipation_s;
        r["apex_minus_papt_s"] = p.apex_s - p.papt_s;
        r["costs"] = {{"smooth", p.smooth_cost}, {"intensity", p.intensity_cost}, {"time", p.time_cost}};
        r["intensity_rule"] = p.intensity_ok;
        r["early_exit"] = p.early_exit;
        r["memory_waived"] = p.memory_waived;
        r["intensity_rule_possible"] = p.intensity_possible;
      } else {
        r["apex_s"] = nullptr;
        r["reason"] = p.skipped_reason;
      }
      rows.push_back(std::move(r));
    }
    Json rep{{"file", a.file},
             {"algorithm", a.algorithm},
             {"duration_s", duration_s},
             {"synchrony_window_s", {sp.synchrony_min_s, sp.synchrony_max_s}},
             {"anticipation", "PAPT - apex (thesis 4.4.3: positive = apex before the PAPT)"},
             {"phrases", g.num_phrases()},
             {"synchrony_rate", synth->synchrony_rate},
             {"intensity_rule_rate", synth->intensity_rule_rate},
             {"intensity_rule_rate_where_possible", synth->intensity_rule_rate_where_possible},
             {"compute_s", synth->compute_s},
             {"feet_planted", synth->feet_planted},
             {"speed_limit_m_s", synth->speed_limit_m_s},
             {"speed_max_before_m_s", synth->speed_max_before_m_s},
             {"speed_limited_frames", synth->speed_limited_frames},
             {"phones", phones.size()},
             {"recognizer", recognizer_ran},
             {"accents", std::move(rows)}};
    if (auto st = WriteText(a.report, rep.dump(1), "--report"); !st.ok()) Fail(cmd, st);
  }
  int placed = 0;
  for (const auto& p : synth->report) placed += p.placed;
  std::printf("%s: %.2f s, %zu accents, %d placed, synchrony %.3f, intensity rule %.3f, %zu phones, %.1f ms\n",
              a.file.c_str(), duration_s, accents.size(), placed, synth->synchrony_rate, synth->intensity_rule_rate,
              phones.size(), synth->compute_s * 1000);
}

}  // namespace cmd_gestures
}  // namespace

void RegisterGestureCommands(CLI::App& app) {
  using namespace cmd_gestures;
  CLI::App* gmg = app.add_subcommand("gmg", "Gesture Motion Graph: Table 4.2 sweep, gesture phrases");
  gmg->require_subcommand(1);
  {
    auto a = std::make_shared<SweepArgs>();
    CLI::App* c = gmg->add_subcommand("sweep", "Size, BF, SCC size and SCC BF per similarity threshold");
    AddLibraryOptions(c, &a->lib);
    c->add_option("--thresholds", a->thresholds, "Comma-separated similarity thresholds")->capture_default_str();
    c->add_flag("--json", a->json, "Print [{st, size, bf, scc_size, scc_bf}]");
    c->callback([a] { RunSweep(*a); });
  }
  {
    auto a = std::make_shared<LibraryArgs>();
    CLI::App* c = gmg->add_subcommand("phrases", "Automatic gesture phrases as a correctable manifest (JSON)");
    AddLibraryOptions(c, a.get());
    c->callback([a] { RunPhrases(*a); });
  }
  auto a = std::make_shared<GesturesArgs>();
  CLI::App* c = app.add_subcommand("gestures", "Gestures and visemes for a speech recording (GMG / BodySpeech)");
  c->add_option("FILE", a->file, "Speech audio (WAV, FLAC, ...)")->required();
  AddLibraryOptions(c, &a->lib);
  c->add_option("-o,--out", a->out_bvh, "Output BVH (required)");
  AddDeprecatedOption(c, "--output", "--out", a->out_bvh);
  c->add_option("--visemes", a->visemes, "Viseme tracks (.json or .csv)");
  c->add_option("--report", a->report, "Per-accent report (JSON)");
  c->add_option("--accents", a->accents_file,
                "Pitch accents from a file (kinemo prosody --json output or [{time_s, strength, psi}]) "
                "instead of the analysis");
  c->add_option("--algorithm", a->algorithm, "bodyspeech or gmg")->capture_default_str();
  c->add_option("--st", a->similarity_threshold, "GMG similarity threshold")->capture_default_str();
  c->add_option("--gesture-emphasis", a->gesture_emphasis, "Gesture style slider in [-1, 1]")
      ->capture_default_str();
  c->add_option("--face-emphasis", a->face_emphasis, "Face (viseme) emphasis slider in [-1, 1]")
      ->capture_default_str();
  c->add_option("--accent-threshold", a->accent_threshold,
                "Accent detector: strength-indicator threshold, share of the maximum")
      ->capture_default_str();
  c->add_option("--min-accent-distance", a->min_accent_distance_s, "Accent detector: minimum time between accents")
      ->capture_default_str();
  c->add_option("--seed", a->seed, "Seed of the anticipation draws (0 = fixed)")->capture_default_str();
  c->add_flag("--no-recognize", a->no_recognize, "Skip the recognizer (visemes then show silence)");
  c->add_flag("--no-stroke-phrases", a->no_stroke_phrases,
              "BodySpeech: do not add each stroke as a phrase of its own (§4.5.1)");
  c->add_flag("--no-plant-feet", a->no_plant_feet, "Leave the feet as synthesised (no contact planting)");
  c->callback([a] {
    if (a->out_bvh.empty()) {
      std::cerr << "kinemo gestures: --out is required\n";
      throw CliExit{2};
    }
    RunGestures(*a);
  });
}

}  // namespace kinemo::cli
