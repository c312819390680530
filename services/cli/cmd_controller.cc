// `kinemo controller ...`: the Gesture Controller control layer.
//
//   kinemo controller build --library DIR --model MODEL --out CTRL [--json]
//   kinemo controller build --server ADDR --library-id L --model-id M --id C
//                           [--overwrite] [--inference-server ADDR] [--json]
//   ... build (either form) --tones-from PATH ...: tones estimated from styled
//       vs normal takes (Bandai-named BVH files or folders), applied to the
//       library (services/planner/controller/tones.h)
//       (server-side: the model's parameters from the inference service's
//        GetModel, then the planner's BuildController; progress on stderr)
//   kinemo controller push CTRL --id ID --library LIB[@V] [--overwrite] [--json]
//   kinemo controller ls [--all] [--json]
//   kinemo controller rm ID[@VERSION]
//   kinemo controller synthesize --controller CTRL --speech FILE.wav --out OUT.bvh
//                                [--model MODEL] [--keyword WORD@END_S ...]
//                                [--style TONE=W ...] [--online] [--json]
//                                [--policy dp|online|random] [--seed N]
//   kinemo controller tones PATH... [--json]
//       (tones from styled capture: the T_m that --tones-from would apply)
//   kinemo controller bench [--json] [--data-root ../shared/data] [--work-dir DIR]
//                           [--minutes 1,5,12] [--states 10]
//
// MODEL is an inference model file (`kinemo crf train`): its hidden-state
// Gaussians over the six kinematic parameters and its transition matrix T
// drive the controller; `synthesize` also uses it to infer beliefs from the
// speech's prosody.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/grpc/status_mapping.h"
#include "common/motion/bvh.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "services/cli/artifact_commands.h"
#include "services/cli/commands.h"
#include "services/cli/proto_json.h"
#include "services/inference/core/model_store.h"
#include "services/inference/core/remapped_model.h"
#include "services/inference/corpus/corpus.h"
#include "services/planner/controller/controller.h"
#include "services/planner/controller/controller_proto.h"
#include "services/planner/controller/tones.h"
#include "services/planner/library/library.h"

namespace kinemo::cli {
namespace {
namespace cmd_controller {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;
namespace ctl = planner::controller;

[[noreturn]] void Fail(const Status& status) {
  FailCommand("controller", status, {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound,
                              absl::StatusCode::kAlreadyExists});
}

template <typename T>
T OrFail(StatusOr<T> v) {
  if (!v.ok()) Fail(v.status());
  return *std::move(v);
}

void OrFail(const Status& s) {
  if (!s.ok()) Fail(s);
}

struct LoadedModel {
  inference::RemappedModel model;
  ctl::StateModel states;
};

LoadedModel LoadModel(const std::string& path) {
  auto file = OrFail(inference::ReadModelFile(path));
  LoadedModel m;
  m.model = OrFail(inference::DecodeModel(file));
  m.states = OrFail(ctl::FromProto(inference::MakeModelParameters(m.model)));
  return m;
}

// Smoothed beliefs γ for a speech file.
std::vector<ctl::BeliefSpan> BeliefsOf(const inference::RemappedModel& model, const std::string& wav,
                                       double* duration_s) {
  auto speech = OrFail(inference::ReadSpeechFile(wav));
  auto track = OrFail(inference::ExtractProsodyWithProsodyCore(speech.samples, speech.sample_rate_hz));
  *duration_s = static_cast<double>(speech.samples.size()) / speech.sample_rate_hz;
  if (track.steps.empty()) Fail(InvalidField(wav, "no syllables found"));
  auto inf = OrFail(model.Infer(track.steps, false, false));
  std::vector<ctl::BeliefSpan> out;
  for (size_t t = 0; t < track.steps.size(); ++t) {
    ctl::BeliefSpan b;
    b.start_s = track.steps[t].start_s;
    b.end_s = track.steps[t].end_s;
    const auto row = inf.smoothed.row(static_cast<Eigen::Index>(t));
    double sum = row.sum();
    for (Eigen::Index i = 0; i < row.size(); ++i) b.probabilities.push_back(row(i) / sum);
    out.push_back(std::move(b));
  }
  return out;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * static_cast<double>(v.size() - 1))];
}

nlohmann::json BuildJson(const ctl::BuildReport& r) {
  return {{"library_s", r.library_s}, {"segments", r.segments}, {"entries", r.entries},
          {"culled_fraction", r.culled_fraction}, {"train_s", r.train_s}};
}

// ---------------------------------------------------------------------------
struct BuildFlags {
  std::string library, model, out;
  std::vector<std::string> tones, tones_from;
  int threads = 0;
  bool json = false, no_cull = false;
  double meters_per_unit = 0;
  // Server-side build.
  std::string server, inference_server, library_id, model_id, id;
  bool overwrite = false;
  double timeout_s = 600;
};

std::chrono::system_clock::time_point Deadline(double s) {
  return std::chrono::system_clock::now() + std::chrono::milliseconds(static_cast<long long>(s * 1000));
}

// The tones of --tones-from (none without it).
std::vector<ctl::ToneTransfer> TonesFrom(const BuildFlags& f) {
  if (f.tones_from.empty()) return {};
  return OrFail(ctl::EstimateTones(f.tones_from, ctl::DefaultToneEstimationOptions(), "--tones-from"));
}

// BuildController on the planner at f.server, with the state model of the
// inference model f.model_id (GetModel at the same address, or
// f.inference_server).
void RunServerBuild(const BuildFlags& f) {
  for (const auto& [flag, value] : {std::pair<const char*, const std::string*>{"--library-id", &f.library_id},
                                    {"--model-id", &f.model_id}, {"--id", &f.id}}) {
    if (value->empty()) Fail(InvalidField(flag, "needed with --server"));
  }
  const std::string inference_address = f.inference_server.empty() ? f.server : f.inference_server;
  inference::v1::GetModelRequest greq;
  greq.set_model_id(f.model_id);
  greq.set_include_parameters(true);
  inference::v1::GetModelResponse model;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(30));
    const grpc::Status s =
        inference::v1::InferenceService::NewStub(ServerChannel(inference_address))->GetModel(&ctx, greq, &model);
    if (!s.ok()) Fail(Annotate(FromGrpcStatus(s, "inference"), "--model-id"));
  }
  planner::v1::BuildControllerRequest req;
  req.set_controller_id(f.id);
  req.set_library_id(f.library_id);
  req.set_inference_model_id(f.model_id);
  req.set_overwrite(f.overwrite);
  // planner.v1.StateModel is wire-compatible with inference.v1.ModelParameters.
  if (!req.mutable_state_model()->ParseFromString(model.parameters().SerializeAsString())) {
    Fail(absl::InternalError("--model-id: the model's parameters do not decode as a state model"));
  }
  for (const auto& t : f.tones) req.mutable_params()->add_tones(t);
  for (const auto& t : TonesFrom(f)) *req.mutable_params()->add_tone_transforms() = ctl::ToneTransformToProto(t);
  req.mutable_params()->set_threads(static_cast<uint32_t>(std::max(0, f.threads)));
  req.mutable_params()->set_disable_culling(f.no_cull);
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(f.timeout_s));
  auto reader = planner::v1::PlannerService::NewStub(ServerChannel(f.server))->BuildController(&ctx, req);
  planner::v1::BuildControllerResponse msg;
  planner::v1::ControllerInfo info;
  std::string stage;
  double printed = -1;
  while (reader->Read(&msg)) {
    if (msg.has_controller()) info = msg.controller();
    const auto& p = msg.progress();
    if (p.stage() != stage || p.fraction() >= printed + 0.1) {
      stage = p.stage();
      printed = p.fraction();
      std::cerr << "kinemo controller build: " << p.stage() << " " << static_cast<int>(100 * p.stage_fraction())
                << " % (" << static_cast<int>(100 * p.fraction()) << " % of the build, " << p.elapsed_s() << " s)\n";
    }
  }
  const grpc::Status s = reader->Finish();
  if (!s.ok()) Fail(FromGrpcStatus(s, "planner"));
  if (f.json) {
    std::cout << ProtoJson(info) << "\n";
    return;
  }
  std::cout << "stored controllers/" << info.controller_id() << "/" << info.version() << " on libraries/"
            << info.library_id() << "/" << info.library_version() << ": " << info.segments() << " segments, "
            << info.num_states() << " states, " << info.tones_size() << " tones, " << info.entries() << " entries ("
            << 100 * info.culled_fraction() << " % culled), built in " << info.train_s() << " s\n";
}

void RunBuild(const BuildFlags& f) {
  if (!f.server.empty()) {
    RunServerBuild(f);
    return;
  }
  for (const auto& [flag, value] : {std::pair<const char*, const std::string*>{"--library", &f.library},
                                    {"--model", &f.model}, {"--out", &f.out}}) {
    if (value->empty()) Fail(InvalidField(flag, "needed (or --server for a server-side build)"));
  }
  LoadedModel m = LoadModel(f.model);
  planner::LibrarySources src;
  src.paths.push_back(fs::absolute(f.library).string());
  src.meters_per_unit = f.meters_per_unit;
  auto library = OrFail(planner::LoadLibrary("cli", src));
  ctl::ControllerParams p;
  p.tones = f.tones;
  p.tone_transfers = TonesFrom(f);
  p.threads = f.threads;
  p.disable_culling = f.no_cull;
  ctl::BuildReport report;
  auto c = OrFail(ctl::Controller::Build(library, m.states, p, nullptr, &report));
  OrFail(c->Save(f.out, src.paths, fs::absolute(f.model).string()));
  if (f.json) {
    std::cout << BuildJson(report).dump() << "\n";
    return;
  }
  std::cout << "library " << report.library_s << " s, " << report.segments << " segments, " << report.end_points
            << " end points, " << c->style_tones().size() << " tones, " << c->keywords().size() << " keywords\n"
            << "entries kept " << report.entries << " (" << 100 * report.culled_fraction << " % of "
            << report.entries_total << " culled)\n"
            << "train " << report.train_s << " s (segments " << report.segment_s << ", delta " << report.delta_s
            << ", value iteration " << report.value_iteration_s << " in " << report.iterations << " sweeps, culling "
            << report.culling_s << ")\n";
  for (const auto& w : report.warnings) std::cout << "warning: " << w << "\n";
}

// ---------------------------------------------------------------------------
// `kinemo controller tones PATH...`: the tone table.
void RunTones(const std::vector<std::string>& paths, bool json) {
  const auto tones = OrFail(ctl::EstimateTones(paths, ctl::DefaultToneEstimationOptions(), "PATH"));
  static const char* kNames[6] = {"T", "D", "V", "A", "C", "H"};
  if (json) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& t : tones) {
      nlohmann::json shift, factor;
      for (int k = 0; k < 6; ++k) {
        shift[kNames[k]] = t.shift(k);
        factor[kNames[k]] = std::exp(t.shift(k));
      }
      out.push_back({{"tone", t.name}, {"source", t.source}, {"actions", t.actions},
                     {"neutral_segments", t.neutral_segments}, {"tone_segments", t.tone_segments},
                     {"shift", shift}, {"factor", factor}});
    }
    std::cout << out.dump() << "\n";
    return;
  }
  std::printf("%-10s %-28s %8s  %6s %6s %6s %6s %6s %6s   (factor exp(shift) on T D V A C H)\n", "tone", "source",
              "segments", "T", "D", "V", "A", "C", "H");
  for (const auto& t : tones) {
    std::printf("%-10s %-28s %3d/%-4d  %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f\n", t.name.c_str(), t.source.c_str(),
                t.tone_segments, t.neutral_segments, std::exp(t.shift(0)), std::exp(t.shift(1)), std::exp(t.shift(2)),
                std::exp(t.shift(3)), std::exp(t.shift(4)), std::exp(t.shift(5)));
  }
}

// ---------------------------------------------------------------------------
struct SynthFlags {
  std::string controller, speech, out, model;
  std::vector<std::string> keywords, style;
  std::string policy = "dp";
  std::uint64_t seed = 1;
  bool online = false, json = false, no_plant_feet = false;
};

void RunSynthesize(const SynthFlags& f) {
  auto c = OrFail(ctl::Controller::Load(f.controller));
  const std::string model_path = !f.model.empty() ? f.model : c->inference_model_path();
  if (model_path.empty()) Fail(InvalidField("--model", "needed (the controller file does not name one)"));
  LoadedModel m = LoadModel(model_path);
  if (m.states.num_states() != c->num_states())
    Fail(InvalidField("--model", "has ", m.states.num_states(), " states, the controller ", c->num_states()));
  double duration = 0;
  const auto beliefs = BeliefsOf(m.model, f.speech, &duration);
  ctl::SynthesisOptions o;
  o.duration_s = duration;
  o.feet.enabled = !f.no_plant_feet;
  for (const auto& k : f.keywords) {
    const auto at = k.find('@');
    if (at == std::string::npos) Fail(InvalidField("--keyword", "'", k, "' must be WORD@END_S"));
    const double end = std::atof(k.c_str() + at + 1);
    o.keywords.push_back({k.substr(0, at), std::max(0.0, end - 0.3), end});
  }
  std::vector<std::pair<std::string, double>> w;
  for (const auto& s : f.style) {
    const auto eq = s.find('=');
    if (eq == std::string::npos) Fail(InvalidField("--style", "'", s, "' must be TONE=WEIGHT"));
    w.emplace_back(s.substr(0, eq), std::atof(s.c_str() + eq + 1));
  }
  o.style = OrFail(ctl::StyleFromWeights(*c, w));
  std::vector<double> decide_us;
  const std::string policy = f.online ? "online" : f.policy;
  if (policy != "dp" && policy != "online" && policy != "random") {
    Fail(InvalidField("--policy", "'", f.policy, "' must be dp, online or random"));
  }
  auto r = policy == "online"   ? OrFail(ctl::RunOnline(*c, beliefs, o, &decide_us))
           : policy == "random" ? OrFail(ctl::SynthesizeRandom(*c, beliefs, o, f.seed))
                                : OrFail(ctl::Synthesize(*c, beliefs, o));
  OrFail(motion::WriteBvhFile(r.clip, f.out));
  nlohmann::json delays = nlohmann::json::array();
  for (const auto& kw : o.keywords) {
    double best = -1;
    for (const auto& p : r.plays)
      if (p.keyword == kw.word && p.end_s > kw.start_s - 1.0) {
        best = p.start_s - kw.end_s;
        break;
      }
    delays.push_back({{"word", kw.word}, {"end_s", kw.end_s}, {"stroke_start_minus_word_end_s", best}});
  }
  nlohmann::json j = {{"duration_s", duration},
                      {"frames", r.clip.num_frames()},
                      {"segments_played", r.plays.size()},
                      {"max_transition_dps", r.max_transition_dps},
                      {"max_inside_dps", r.max_inside_dps},
                      {"library_p99_dps", r.library_p99_dps},
                      {"compute_s", r.compute_s},
                      {"feet_planted", r.feet_planted},
                      {"keywords", delays}};
  if (!r.feet_note.empty()) j["feet_note"] = r.feet_note;
  j["policy"] = policy;
  if (policy == "online") j["decide_us_p99"] = Percentile(decide_us, 0.99);
  if (f.json) {
    std::cout << j.dump() << "\n";
  } else {
    std::cout << "wrote " << f.out << ": " << duration << " s, " << r.plays.size() << " segments played; largest "
              << "joint angular speed at transitions " << r.max_transition_dps << " deg/s (library p99 "
              << r.library_p99_dps << ")\n";
  }
}

// ---------------------------------------------------------------------------
struct BenchFlags {
  std::string root = "../shared/data", work = "/tmp/kinemo_controller_bench", minutes = "12";
  int states = 10;
  bool json = false;
};

std::vector<std::string> GestureClips(const std::string& root, std::string* note) {
  std::vector<std::string> out;
  for (const auto& dir : {fs::path(root) / "motion/bandai-dataset-1"}) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      const std::string n = e.path().filename().string();
      if (e.path().extension() != ".bvh") continue;
      for (const char* g : {"_bow_", "_bye_", "_byebye_", "_call_", "_guide_", "_respond_"})
        if (n.find(g) != std::string::npos) out.push_back(fs::absolute(e.path()).string());
    }
  }
  if (!out.empty()) {
    *note = kinemo::StrCat(root, "/motion/bandai-dataset-1 (bow, bye, byebye, call, guide, respond)");
  } else {
    const fs::path t = fs::path(KINEMO_CLI_TEST_DATA_DIR) / "planner_controller";
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(t, ec))
      if (e.path().extension() == ".bvh") out.push_back(fs::absolute(e.path()).string());
    *note = kinemo::StrCat(t.string(), " (../shared/data not found)");
  }
  std::sort(out.begin(), out.end());
  return out;
}

// A manifest of `clips` repeated until `minutes` is reached; keyword tags from
// the Bandai content (bye/byebye -> "bye", bow -> "bow", guide -> "this").
std::string WriteManifest(const std::vector<std::string>& clips, const std::vector<double>& seconds, double minutes,
                          const fs::path& path, int* repeats) {
  nlohmann::json clips_j = nlohmann::json::array();
  double total = 0;
  *repeats = 0;
  for (int r = 0; total < minutes * 60 && r < 1000; ++r) {
    *repeats = r + 1;
    for (size_t k = 0; k < clips.size() && total < minutes * 60; ++k) {
      const std::string stem = fs::path(clips[k]).stem().string();
      nlohmann::json c = {{"path", clips[k]}, {"name", kinemo::StrCat(stem, "_r", r)}};
      auto b = planner::ParseBandaiName(stem);
      if (b && (b->content == "bye" || b->content == "byebye")) c["keywords"] = {"bye"};
      if (b && b->content == "bow") c["keywords"] = {"bow"};
      if (b && b->content == "guide") c["keywords"] = {"this"};
      clips_j.push_back(c);
      total += seconds[k];
    }
  }
  std::ofstream(path) << nlohmann::json{{"clips", clips_j}}.dump(1);
  return path.string();
}

void RunBench(const BenchFlags& f) {
  fs::create_directories(f.work);
  std::string note;
  const auto clips = GestureClips(f.root, &note);
  if (clips.empty()) Fail(absl::NotFoundError("no gesture clips found"));
  std::vector<double> seconds;
  for (const auto& c : clips) {
    auto clip = OrFail(motion::ReadBvhFile(c));
    seconds.push_back(clip.duration_s());
  }
  double unique_s = 0;
  for (double s : seconds) unique_s += s;
  // Model: a CRF trained on a synthetic pairing of the bundled speech and the
  // gesture clips (inference corpus builder).
  const fs::path model_path = fs::path(f.work) / kinemo::StrCat("crf_", f.states, ".kmodel");
  if (!fs::exists(model_path)) {
    inference::SyntheticCorpusOptions co;
    const fs::path speech_dir = fs::path(KINEMO_CLI_TEST_DATA_DIR) / "speech";
    for (const auto& e : fs::directory_iterator(speech_dir))
      if (e.path().extension() == ".wav") co.speech_files.push_back(e.path().string());
    std::sort(co.speech_files.begin(), co.speech_files.end());
    co.gesture_files = clips;
    co.out_dir = (fs::path(f.work) / "corpus").string();
    co.renditions = 4;
    OrFail(inference::BuildSyntheticCorpus(co).status());
    auto data = OrFail(inference::ImportPairedCorpus(co.out_dir));
    inference::ModelTrainParams tp;
    tp.num_states = f.states;
    tp.hmm_restarts = 2;
    inference::TrainReport tr;
    auto model = OrFail(inference::RemappedModel::Train(data, tp, nullptr, &tr));
    auto info = inference::MakeModelInfo(model, tp, tr, static_cast<std::uint32_t>(data.size()), "controller bench");
    OrFail(inference::WriteModelFile(model_path.string(), inference::EncodeModel(model, info)));
  }
  LoadedModel m = LoadModel(model_path.string());
  const fs::path speech = fs::path(KINEMO_CLI_TEST_DATA_DIR) / "speech/sense_and_sensibility_01_austen_64kb-0870.wav";
  double speech_s = 0;
  const auto beliefs = BeliefsOf(m.model, speech.string(), &speech_s);

  std::vector<double> minutes;
  std::stringstream ss(f.minutes);
  for (std::string tok; std::getline(ss, tok, ',');) minutes.push_back(std::atof(tok.c_str()));
  nlohmann::json rows = nlohmann::json::array();
  nlohmann::json last;
  for (double mins : minutes) {
    int repeats = 0;
    const std::string manifest = WriteManifest(clips, seconds, mins, fs::path(f.work) / kinemo::StrCat("library_", mins, "min.json"), &repeats);
    planner::LibrarySources src;
    src.paths.push_back(manifest);
    auto library = OrFail(planner::LoadLibrary("bench", src));
    ctl::BuildReport report;
    auto c = OrFail(ctl::Controller::Build(library, m.states, ctl::ControllerParams{}, nullptr, &report));
    // Online decisions over the speech, repeated to get enough samples.
    std::vector<double> us;
    ctl::SynthesisOptions o;
    o.keywords.push_back({"bye", 1.0, 1.4});
    for (int rep = 0; rep < 5; ++rep) OrFail(ctl::RunOnline(*c, beliefs, o, &us).status());
    auto offline = OrFail(ctl::Synthesize(*c, beliefs, o));
    nlohmann::json row = BuildJson(report);
    row["decide_us_p99"] = Percentile(us, 0.99);
    row["decide_us_p50"] = Percentile(us, 0.5);
    row["decisions"] = us.size();
    row["end_points"] = report.end_points;
    row["entries_total"] = report.entries_total;
    row["value_iteration_sweeps"] = report.iterations;
    row["states"] = c->num_states();
    row["tones"] = c->style_tones();
    row["keywords"] = c->keywords();
    row["clip_repeats"] = repeats;
    row["synthesis_max_transition_dps"] = offline.max_transition_dps;
    row["library_p99_dps"] = offline.library_p99_dps;
    row["synthesis_s_per_speech_s"] = offline.compute_s / speech_s;
    rows.push_back(row);
    last = row;
    if (!f.json) {
      std::cout << "library " << report.library_s << " s (clips repeated " << repeats << "x), " << report.segments
                << " segments: train " << report.train_s << " s, " << 100 * report.culled_fraction
                << " % culled, decide p99 " << row["decide_us_p99"].get<double>() << " us\n";
    }
  }
  if (f.json) {
    nlohmann::json out = {{"library_s", last["library_s"]},
                          {"segments", last["segments"]},
                          {"entries", last["entries"]},
                          {"culled_fraction", last["culled_fraction"]},
                          {"train_s", last["train_s"]},
                          {"decide_us_p99", last["decide_us_p99"]},
                          {"unique_clip_s", unique_s},
                          {"clips", note},
                          {"model", kinemo::StrCat("CRF, ", m.states.num_states(), " states, trained on a synthetic pairing of tests/data speech and the gesture clips")},
                          {"rows", rows}};
    std::cout << out.dump() << "\n";
  }
}

// ---------------------------------------------------------------------------
struct PushFlags {
  std::string file, id, library, description, server = DefaultServer();
  bool overwrite = false, json = false;
};

void RunPush(const PushFlags& f) {
  PushSpec spec;
  spec.kind = "controllers";
  spec.id = f.id;
  spec.overwrite = f.overwrite;
  spec.description = f.description.empty() ? kinemo::StrCat("kinemo controller push ", f.file) : f.description;
  spec.files.emplace_back("controller.kctrl", f.file);
  auto library = ParseArtifactRef("libraries", f.library, "--library");
  if (!library.ok()) Fail(library.status());
  spec.depends_on.push_back(*library);
  RunArtifactPush("controller", spec, f.server, f.json);
}

}  // namespace cmd_controller
}  // namespace

void RegisterControllerCommands(CLI::App& app) {
  using namespace cmd_controller;
  CLI::App* ctl_app =
      app.add_subcommand("controller", "Gesture Controller: build, synthesize, bench; stored controllers: push, ls, rm");
  ctl_app->require_subcommand(1);

  auto bf = std::make_shared<BuildFlags>();
  CLI::App* build = ctl_app->add_subcommand(
      "build", "Build a controller from a motion library and an inference model (locally, or on a server)");
  build->add_option("--library", bf->library, "BVH folder, file or JSON manifest (local build)");
  build->add_option("--model", bf->model, "Inference model file, kinemo crf train (local build)");
  build->add_option("-o,--out", bf->out, "Controller file to write (local build)");
  build->add_option("--server", bf->server,
                    "Build on this planner or coordinator and store it there (else: locally into --out)");
  build->add_option("--library-id", bf->library_id, "Stored library to build on (with --server)");
  build->add_option("--model-id", bf->model_id, "Inference model whose states drive it (with --server)");
  build->add_option("--id", bf->id, "Id to store the controller under (with --server)");
  build->add_option("--inference-server", bf->inference_server,
                    "Where the model is, if not at --server (e.g. the inference service's own address)");
  build->add_option("--timeout-s", bf->timeout_s, "Deadline of a server-side build (default 600)");
  build->add_flag("--overwrite", bf->overwrite, "Store a new version when the id exists (with --server)");
  build->add_option("--tones", bf->tones, "Tones to build (default: all of the library and of --tones-from)");
  build->add_option("--tones-from", bf->tones_from,
                    "Estimate tones from styled capture: Bandai-named BVH files or folders "
                    "(<prefix>_<action>_<style>_<take>.bvh; angry, happy, sad -> subdued, active -> energetic, "
                    "each vs the normal takes of the same actions) and apply them to the library");
  build->add_option("--threads", bf->threads, "Threads (default: cores)");
  build->add_option("--meters-per-unit", bf->meters_per_unit, "Skeleton scale (default: manifest or estimate)");
  build->add_flag("--no-cull", bf->no_cull, "Keep every table entry");
  build->add_flag("--json", bf->json,
                  "Print {library_s, segments, entries, culled_fraction, train_s} (with --server: the ControllerInfo)");
  build->callback([bf] { RunBuild(*bf); });

  auto tone_paths = std::make_shared<std::vector<std::string>>();
  auto tone_json = std::make_shared<bool>(false);
  CLI::App* tones = ctl_app->add_subcommand(
      "tones", "Tones from styled capture: per tone, the factors on T D V A C H that --tones-from applies");
  tones->add_option("PATH", *tone_paths, "Bandai-named BVH files or folders")->required();
  tones->add_flag("--json", *tone_json, "Print JSON");
  tones->callback([tone_paths, tone_json] { RunTones(*tone_paths, *tone_json); });

  auto sf = std::make_shared<SynthFlags>();
  CLI::App* synth = ctl_app->add_subcommand("synthesize", "Speech -> prosody -> beliefs -> motion (BVH)");
  synth->add_option("--controller", sf->controller, "Controller file")->required();
  synth->add_option("--speech", sf->speech, "Speech file (WAV)")->required();
  synth->add_option("-o,--out", sf->out, "BVH to write")->required();
  synth->add_option("--model", sf->model, "Inference model (default: the one the controller was built with)");
  synth->add_option("--keyword", sf->keywords, "Spotted keyword WORD@END_S (repeatable)");
  synth->add_option("--style", sf->style, "Tone weight TONE=W (repeatable; default neutral)");
  synth->add_flag("--online", sf->online, "Use the online policy (filtered-belief MDP) instead of the DP");
  synth->add_option("--policy", sf->policy,
                    "dp (offline DP, default), online (as --online) or random (baseline: random segments of the "
                    "library in random order, same blending and feet)")
      ->capture_default_str();
  synth->add_option("--seed", sf->seed, "Seed of --policy random")->capture_default_str();
  synth->add_flag("--no-plant-feet", sf->no_plant_feet, "Leave the feet as assembled (no contact planting)");
  synth->add_flag("--json", sf->json, "Print a JSON report");
  synth->callback([sf] { RunSynthesize(*sf); });

  auto nf = std::make_shared<BenchFlags>();
  CLI::App* bench = ctl_app->add_subcommand("bench", "Table 1: training time, culling, decision latency");
  bench->add_option("--data-root", nf->root, "Where motion/ is (default ../shared/data; else tests/data)");
  bench->add_option("--work-dir", nf->work, "Scratch directory (model and manifests are cached here)");
  bench->add_option("--minutes", nf->minutes, "Library sizes in minutes, comma-separated (default 12)");
  bench->add_option("--states", nf->states, "Hidden states of the bench model (default 10)");
  bench->add_flag("--json", nf->json, "Print {library_s, segments, entries, culled_fraction, train_s, decide_us_p99}");
  bench->callback([nf] { RunBench(*nf); });

  auto pf = std::make_shared<PushFlags>();
  CLI::App* push = ctl_app->add_subcommand("push", "Upload a controller file built by `controller build --out`");
  push->add_option("CTRL", pf->file, "Controller file (.kctrl)")->required();
  push->add_option("--id", pf->id, "Id to store it under ([a-z0-9_-]{1,64})")->required();
  push->add_option("--library", pf->library,
                   "Stored library it was built on, ID or ID@VERSION (kinemo library push the same sources)")
      ->required();
  push->add_option("--server", pf->server, "Address of the planner or a coordinator (default $KINEMO_SERVER or localhost:50050)");
  push->add_option("--description", pf->description, "Free text stored with it");
  push->add_flag("--overwrite", pf->overwrite, "Store a new version when the id exists");
  push->add_flag("--json", pf->json, "Print the stored ArtifactInfo as JSON");
  push->callback([pf] { RunPush(*pf); });

  AddArtifactListAndRemove(ctl_app, "controller", {"controllers"});
}

}  // namespace kinemo::cli
