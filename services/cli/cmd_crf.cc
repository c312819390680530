// `kinemo crf ...`: build a paired corpus, train and evaluate the remapped
// CRF, replicate Gesture Controllers Fig. 4, and benchmark.
//
//   kinemo crf corpus --out DIR [--data-root ../shared/data] [--renditions N] [--seed S]
//                     [--speech FILE...] [--gestures FILE...]
//   kinemo crf train --corpus DIR --states N --window W --out MODEL [--clusters K] ...
//   kinemo crf train --corpus DIR --states N --window W --server ADDR --id ID [--overwrite] ...
//                    (trains on the inference service; the corpus is imported here and sent inline)
//   kinemo crf evaluate --model MODEL --corpus DIR [--json]
//   kinemo crf fig4 --corpus DIR --holdout PREFIX --csv F --png F [--states N]
//   kinemo crf fig4 --paired DIR [--json] [--states N] [--window W] [--csv F] [--png F]
//                    (a corpus recorded together: leave one recording out, every fold)
//   kinemo crf bench [--json] [--data-root ../shared/data] [--work-dir DIR]
//
// The corpora built by `crf corpus` are SYNTHETIC PAIRINGS of real speech and
// real motion capture that were not recorded together (see
// BuildSyntheticCorpus); every report on them says so. `fig4 --paired` is for
// corpora recorded together (BEAT2: tests/data/paired/beat2).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "common/grpc/status_mapping.h"
#include "common/image/png.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "services/cli/artifact_client.h"
#include "services/cli/proto_json.h"
#include "services/cli/commands.h"
#include "services/inference/core/model_store.h"
#include "services/inference/core/remapped_model.h"
#include "services/inference/corpus/corpus.h"

namespace kinemo::cli {
namespace {
namespace cmd_crf {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;
using inference::ModelTrainParams;
using inference::PairedSequence;

constexpr const char* kCorpusNote =
    "synthetic pairing of real speech and real motion capture (not recorded together)";

[[noreturn]] void Fail(const Status& status) {
  FailCommand("crf", status, {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound,
                              absl::StatusCode::kAlreadyExists});
}

template <typename T>
T OrFail(StatusOr<T> v) {
  if (!v.ok()) Fail(v.status());
  return *std::move(v);
}

std::vector<std::string> Sorted(const fs::path& dir, const std::string& ext,
                                const std::vector<std::string>& must_contain_any) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (e.path().extension() != ext) continue;
    bool ok = must_contain_any.empty();
    for (const auto& m : must_contain_any) ok = ok || name.find(m) != std::string::npos;
    if (ok) out.push_back(e.path().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Default inputs from ../shared/data: all speech, Bandai gesture clips.
void DefaultInputs(const std::string& root, std::vector<std::string>* speech,
                   std::vector<std::string>* gestures) {
  if (speech->empty()) {
    for (const char* d : {"speech/librivox", "speech/zeggs"}) {
      auto f = Sorted(fs::path(root) / d, ".wav", {});
      speech->insert(speech->end(), f.begin(), f.end());
    }
  }
  if (gestures->empty()) {
    *gestures = Sorted(fs::path(root) / "motion/bandai-dataset-1", ".bvh",
                       {"_bye_", "_byebye_", "_call_", "_guide_", "_respond_"});
  }
  if (speech->empty() || gestures->empty())
    Fail(absl::NotFoundError(kinemo::StrCat(root, ": no speech (speech/librivox, speech/zeggs) or no "
                                            "Bandai gesture clips (motion/bandai-dataset-1) found")));
}

struct TrainFlags {
  std::string corpus, out, description, server, id;
  int states = 25, window = 4, clusters = 10, restarts = 5;
  double l2 = 1.0, timeout_s = 600;
  std::uint64_t seed = 1;
  bool full = false, json = false, minimal = false, overwrite = false;
};

ModelTrainParams ToParams(const TrainFlags& f) {
  ModelTrainParams p;
  p.num_states = f.states;
  p.window = f.window;
  p.num_clusters = f.clusters;
  p.hmm_restarts = f.restarts;
  p.crf_l2 = f.l2;
  p.seed = f.seed;
  p.full_covariance = f.full;
  return p;
}

// Trains on the inference service at f.server: the sequences go inline in
// the Train request, progress goes to stderr, and the stored model's info is
// printed.
void TrainOnServer(const TrainFlags& f, const std::vector<PairedSequence>& data) {
  inference::v1::TrainRequest req;
  req.set_model_id(f.id);
  for (const auto& seq : data) *req.mutable_sequences()->add_sequences() = inference::ToProto(seq);
  *req.mutable_params() = inference::ToProto(ToParams(f));
  req.set_overwrite(f.overwrite);
  req.set_description(f.description.empty() ? kinemo::StrCat("corpus ", f.corpus, " (", kCorpusNote, ")")
                                            : f.description);
  auto stub = inference::v1::InferenceService::NewStub(ServerChannel(f.server));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(static_cast<long long>(f.timeout_s * 1000)));
  auto reader = stub->Train(&ctx, req);
  inference::v1::TrainResponse msg;
  inference::v1::ModelInfo stored;
  while (reader->Read(&msg)) {
    const auto& p = msg.progress();
    std::cerr << "train: " << p.stage() << " " << static_cast<int>(p.fraction() * 100 + 0.5) << "% ("
              << p.elapsed_s() << " s)" << (p.message().empty() ? "" : " " + p.message()) << "\n";
    if (msg.has_model()) stored = msg.model();
  }
  const grpc::Status s = reader->Finish();
  if (!s.ok()) Fail(FromGrpcStatus(s, "inference"));
  if (f.json) {
    std::cout << ProtoJson(stored) << "\n";
  } else {
    std::cout << "stored model '" << stored.model_id() << "' version " << stored.version() << " at " << f.server
              << ": " << stored.num_states() << " states, window " << stored.window() << ", "
              << stored.training_sequences() << " sequences (" << stored.training_data_s() << " s), trained in "
              << stored.train_s() << " s; CRF " << stored.train_crf_ll_per_step() << " vs HMM "
              << stored.train_hmm_ll_per_step() << " log-likelihood per step\n";
  }
}

struct Scores {
  double crf = 0, hmm = 0;
  std::uint64_t steps = 0;
};
Scores EvaluateAll(const inference::RemappedModel& model, const std::vector<PairedSequence>& data) {
  Scores s;
  for (const auto& seq : data) {
    auto sc = OrFail(model.Evaluate(seq));
    s.crf += sc.crf_ll_per_step * static_cast<double>(sc.steps);
    s.hmm += sc.hmm_ll_per_step * static_cast<double>(sc.steps);
    s.steps += sc.steps;
  }
  if (s.steps > 0) {
    s.crf /= static_cast<double>(s.steps);
    s.hmm /= static_cast<double>(s.steps);
  }
  return s;
}

void WritePlot(const std::string& path, const std::vector<int>& windows,
               const std::vector<Scores>& scores, const std::string& pairing) {
  const int w = 640, h = 420, l = 80, r = 20, t = 40, b = 60;
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  double lo = 1e300, hi = -1e300;
  for (const auto& s : scores) {
    lo = std::min({lo, s.crf, s.hmm});
    hi = std::max({hi, s.crf, s.hmm});
  }
  const double pad = 0.1 * std::max(1e-3, hi - lo);
  lo -= pad;
  hi += pad;
  auto px = [&](double i) { return l + static_cast<int>((i - windows.front()) / std::max(1, windows.back() - windows.front()) * (w - l - r)); };
  auto py = [&](double v) { return t + static_cast<int>((hi - v) / (hi - lo) * (h - t - b)); };
  cv::rectangle(img, {l, t}, {w - r, h - b}, cv::Scalar(0, 0, 0), 1);
  for (int k = 0; k <= 4; ++k) {
    const double v = lo + (hi - lo) * k / 4;
    cv::putText(img, cv::format("%.2f", v), {5, py(v) + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1);
    cv::line(img, {l, py(v)}, {w - r, py(v)}, cv::Scalar(220, 220, 220), 1);
  }
  for (int win : windows)
    cv::putText(img, std::to_string(win), {px(win) - 4, h - b + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 0}, 1);
  cv::putText(img, "input window (steps)", {w / 2 - 80, h - 15}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 0}, 1);
  cv::putText(img, "held-out log-likelihood per step (" + pairing + ")", {l, 25}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 0}, 1);
  const cv::Scalar crf_color(200, 60, 0), hmm_color(0, 0, 200);
  for (size_t k = 0; k < scores.size(); ++k) {
    cv::circle(img, {px(windows[k]), py(scores[k].crf)}, 4, crf_color, cv::FILLED);
    cv::circle(img, {px(windows[k]), py(scores[k].hmm)}, 4, hmm_color, cv::FILLED);
    if (k > 0) {
      cv::line(img, {px(windows[k - 1]), py(scores[k - 1].crf)}, {px(windows[k]), py(scores[k].crf)}, crf_color, 2);
      cv::line(img, {px(windows[k - 1]), py(scores[k - 1].hmm)}, {px(windows[k]), py(scores[k].hmm)}, hmm_color, 2);
    }
  }
  cv::putText(img, "CRF", {l + 10, h - b - 30}, cv::FONT_HERSHEY_SIMPLEX, 0.5, crf_color, 2);
  cv::putText(img, "remapped HMM", {l + 10, h - b - 10}, cv::FONT_HERSHEY_SIMPLEX, 0.5, hmm_color, 2);
  const Status written = image::WritePngFile(path, {img.data, img.cols, img.rows, img.channels(), img.step, true});
  if (!written.ok()) Fail(written);
}

double Percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * static_cast<double>(v.size() - 1))];
}

}  // namespace cmd_crf
}  // namespace

void RegisterCrfCommands(CLI::App& app) {
  using namespace cmd_crf;
  CLI::App* crf = app.add_subcommand("crf", "Remapped CRF: corpus, training, evaluation, Fig. 4, bench");
  crf->require_subcommand(1);

  // --- corpus ---------------------------------------------------------------
  struct CorpusFlags {
    std::string out, root = "../shared/data";
    std::vector<std::string> speech, gestures;
    int renditions = 1;
    std::uint64_t seed = 1;
    bool minimal = false;
  };
  auto cf = std::make_shared<CorpusFlags>();
  CLI::App* corpus = crf->add_subcommand(
      "corpus", "Build a paired corpus (<name>.wav + <name>.bvh) from unpaired real speech and motion");
  corpus->add_option("-o,--out", cf->out, "Output directory")->required();
  corpus->add_option("--data-root", cf->root, "Where speech/ and motion/ are (default ../shared/data)");
  corpus->add_option("--speech", cf->speech, "Speech files (default: all under DATA_ROOT/speech)");
  corpus->add_option("--gestures", cf->gestures, "Gesture BVH clips (default: Bandai bye/byebye/call/guide/respond)");
  corpus->add_option("--renditions", cf->renditions, "Motion renditions per speech file");
  corpus->add_option("--seed", cf->seed, "Random seed");
  corpus->add_flag("--minimal-prosody", cf->minimal, "Use the minimal built-in prosody extractor");
  corpus->callback([cf] {
    DefaultInputs(cf->root, &cf->speech, &cf->gestures);
    inference::SyntheticCorpusOptions o{cf->speech, cf->gestures, cf->out, cf->renditions, cf->seed};
    if (cf->minimal) o.extractor = inference::ExtractProsody;
    auto r = OrFail(inference::BuildSyntheticCorpus(o));
    std::cout << "wrote " << r.recordings << " recordings (" << r.speech_s << " s of speech, "
              << r.gestures_placed << " gestures) to " << cf->out << " — " << kCorpusNote << "\n";
  });

  // --- train ------------------------------------------------------------------
  auto tf = std::make_shared<TrainFlags>();
  CLI::App* train = crf->add_subcommand("train", "Train HMM + clusters + remapped CRF on a paired corpus");
  train->add_option("--corpus", tf->corpus, "Paired corpus directory")->required();
  train->add_option("--states", tf->states, "Hidden states S")->required();
  train->add_option("--window", tf->window, "Input window w")->required();
  train->add_option("-o,--out", tf->out, "Model file to write (or --server)");
  train->add_option("--server", tf->server, "Train on the inference service at ADDR (e.g. the coordinator's); "
                                            "the model is stored there (with --id)");
  train->add_option("--id", tf->id, "With --server: the id the model is stored and called by");
  train->add_flag("--overwrite", tf->overwrite, "With --server: store a new version when the id exists");
  train->add_option("--timeout-s", tf->timeout_s, "With --server: seconds to wait (default 600)");
  AddDeprecatedOption(train, "--timeout", "--timeout-s", tf->timeout_s);
  train->add_option("--clusters", tf->clusters, "Prosody clusters K (default 10)");
  train->add_option("--restarts", tf->restarts, "HMM EM restarts (default 5)");
  train->add_option("--l2", tf->l2, "CRF L2 weight (default 1)");
  train->add_option("--seed", tf->seed, "Seed");
  train->add_option("--description", tf->description, "Stored with the model");
  train->add_flag("--full-covariance", tf->full, "Full-covariance HMM emissions");
  train->add_flag("--json", tf->json, "Print JSON");
  train->add_flag("--minimal-prosody", tf->minimal, "Use the minimal built-in prosody extractor");
  train->callback([tf] {
    if (tf->server.empty() && tf->out.empty()) Fail(InvalidField("--out", "required (or --server ADDR --id ID)"));
    if (!tf->server.empty() && !tf->out.empty()) {
      Fail(InvalidField("--out", "not used with --server (the model is stored on the server: kinemo model ls)"));
    }
    if (!tf->server.empty() && tf->id.empty()) Fail(InvalidField("--id", "required with --server"));
    auto data = OrFail(inference::ImportPairedCorpus(
        tf->corpus, tf->minimal ? inference::ProsodyExtractor(inference::ExtractProsody)
                                : inference::ProsodyExtractor(inference::ExtractProsodyWithProsodyCore)));
    if (!tf->server.empty()) {
      TrainOnServer(*tf, data);
      return;
    }
    const ModelTrainParams p = ToParams(*tf);
    inference::TrainReport report;
    int hmm_iterations = 0;
    auto model = OrFail(inference::RemappedModel::Train(
        data, p,
        [&](std::string_view stage, double, std::string_view message) {
          if (stage == "hmm_em" && !message.empty()) ++hmm_iterations;
          return true;
        },
        &report));
    auto info = inference::MakeModelInfo(model, p, report, static_cast<std::uint32_t>(data.size()),
                                          tf->description.empty() ? kinemo::StrCat("corpus ", tf->corpus)
                                                                  : tf->description);
    info.set_model_id(fs::path(tf->out).stem().string());
    info.set_version(1);
    if (auto st = inference::WriteModelFile(tf->out, inference::EncodeModel(model, info)); !st.ok()) Fail(st);
    nlohmann::json j{{"model", tf->out},          {"sequences", data.size()},
                     {"steps", report.steps},      {"data_s", report.data_s},
                     {"train_s", report.train_s},  {"hmm_ll_per_step", report.hmm_ll_per_step},
                     {"crf_ll_per_step", report.crf_ll_per_step},
                     {"crf_iterations", report.crf_iterations}, {"hmm_s", report.hmm_s},
                     {"clustering_s", report.clustering_s}, {"crf_s", report.crf_s},
                     {"hmm_em_iterations", hmm_iterations}};
    if (tf->json) std::cout << j.dump() << "\n";
    else std::cout << j.dump(2) << "\n";
  });

  // --- evaluate ---------------------------------------------------------------
  struct EvalFlags {
    std::string model, corpus;
    bool json = false, minimal = false;
  };
  auto ef = std::make_shared<EvalFlags>();
  CLI::App* eval = crf->add_subcommand("evaluate", "Held-out log-likelihood per step, CRF vs remapped HMM");
  eval->add_option("--model", ef->model, "Model file")->required();
  eval->add_option("--corpus", ef->corpus, "Paired corpus directory")->required();
  eval->add_flag("--json", ef->json, "Print {crf_ll_per_step, hmm_ll_per_step, steps}");
  eval->add_flag("--minimal-prosody", ef->minimal, "Use the minimal built-in prosody extractor");
  eval->callback([ef] {
    auto file = OrFail(inference::ReadModelFile(ef->model));
    auto model = OrFail(inference::DecodeModel(file));
    auto data = OrFail(inference::ImportPairedCorpus(
        ef->corpus, ef->minimal ? inference::ProsodyExtractor(inference::ExtractProsody)
                                : inference::ProsodyExtractor(inference::ExtractProsodyWithProsodyCore)));
    const Scores s = EvaluateAll(model, data);
    nlohmann::json j{{"crf_ll_per_step", s.crf}, {"hmm_ll_per_step", s.hmm}, {"steps", s.steps}};
    if (ef->json) {
      std::cout << j.dump() << "\n";
    } else {
      std::cout << "CRF " << s.crf << " vs remapped HMM " << s.hmm << " log-likelihood per step over "
                << s.steps << " steps\n";
    }
  });

  // --- fig4 -------------------------------------------------------------------
  struct Fig4Flags {
    std::string corpus, holdout, paired, csv, png;
    int states = 25, clusters = 10, max_window = 5, window = 4;
    double l2 = 1.0;
    std::uint64_t seed = 1;
    bool json = false;
  };
  auto ff = std::make_shared<Fig4Flags>();
  CLI::App* fig4 = crf->add_subcommand("fig4", "Gesture Controllers Fig. 4: CRF vs remapped HMM, windows 1-5");
  fig4->add_option("--corpus", ff->corpus, "Paired corpus directory (with --holdout)");
  fig4->add_option("--holdout", ff->holdout, "Recordings whose name starts with this are held out");
  fig4->add_option("--paired", ff->paired,
                   "A corpus recorded together (<name>.wav + <name>.bvh): every recording held out in turn, "
                   "the others train");
  fig4->add_option("--csv", ff->csv, "CSV output (default fig4.csv with --corpus; none with --paired)");
  fig4->add_option("--png", ff->png, "PNG plot output (default fig4.png with --corpus; none with --paired)");
  fig4->add_option("--states", ff->states, "Hidden states (default 25)");
  fig4->add_option("--clusters", ff->clusters, "Clusters (default 10)");
  fig4->add_option("--l2", ff->l2, "CRF L2 weight");
  fig4->add_option("--max-window", ff->max_window, "Largest window (default 5)");
  fig4->add_option("--window", ff->window, "With --paired: the window of each fold's headline figures (default 4)");
  fig4->add_option("--seed", ff->seed, "Seed");
  fig4->add_flag("--json", ff->json, "With --paired: print {corpus, folds: [{train, test, crf_ll_per_step, "
                                     "hmm_ll_per_step, steps, by_window}]}");
  fig4->callback([ff] {
    if (ff->paired.empty() == ff->corpus.empty())
      Fail(InvalidField("--paired", "give either --paired DIR or --corpus DIR --holdout PREFIX"));
    if (!ff->corpus.empty() && ff->holdout.empty()) Fail(InvalidField("--holdout", "required with --corpus"));
    if (ff->max_window < 1 || ff->max_window > 16) Fail(InvalidField("--max-window", ff->max_window, " is not in [1, 16]"));
    if (ff->window < 1 || ff->window > ff->max_window)
      Fail(InvalidField("--window", ff->window, " is not in [1, --max-window ", ff->max_window, "]"));
    const bool paired = !ff->paired.empty();
    const std::string note = paired ? "recorded together" : kCorpusNote;
    const std::string csv_path = !ff->csv.empty() ? ff->csv : (paired ? "" : "fig4.csv");
    const std::string png_path = !ff->png.empty() ? ff->png : (paired ? "" : "fig4.png");
    auto data = OrFail(inference::ImportPairedCorpus(paired ? ff->paired : ff->corpus));
    // Folds: (train, test) splits.
    struct Fold {
      std::vector<PairedSequence> train, test;
      std::vector<Scores> by_window;
      std::vector<double> train_s;
    };
    std::vector<Fold> folds;
    if (paired) {
      if (data.size() < 2)
        Fail(InvalidField("--paired", ff->paired, " has ", data.size(), " recording(s); leave-one-out needs 2 or more"));
      for (size_t k = 0; k < data.size(); ++k) {
        Fold f;
        for (size_t i = 0; i < data.size(); ++i) (i == k ? f.test : f.train).push_back(data[i]);
        folds.push_back(std::move(f));
      }
    } else {
      Fold f;
      for (auto& s : data) (s.name.rfind(ff->holdout, 0) == 0 ? f.test : f.train).push_back(std::move(s));
      if (f.train.empty() || f.test.empty())
        Fail(absl::InvalidArgumentError(kinemo::StrCat("--holdout ", ff->holdout, ": needs recordings on both sides (",
                                                       f.train.size(), " train, ", f.test.size(), " held out)")));
      folds.push_back(std::move(f));
    }
    std::vector<int> windows;
    for (int w = 1; w <= ff->max_window; ++w) windows.push_back(w);
    for (Fold& f : folds) {
      for (int w : windows) {
        ModelTrainParams p;
        p.num_states = ff->states;
        p.num_clusters = ff->clusters;
        p.window = w;
        p.crf_l2 = ff->l2;
        p.seed = ff->seed;
        inference::TrainReport report;
        auto model = OrFail(inference::RemappedModel::Train(f.train, p, nullptr, &report));
        f.by_window.push_back(EvaluateAll(model, f.test));
        f.train_s.push_back(report.train_s);
        if (!ff->json) {
          const Scores& s = f.by_window.back();
          std::cout << (paired ? kinemo::StrCat("held out ", f.test[0].name, ", ") : std::string()) << "window " << w
                    << ": CRF " << s.crf << "  remapped HMM " << s.hmm << "  (" << s.steps << " held-out steps, train "
                    << report.train_s << " s)\n";
        }
      }
    }
    // Mean over folds per window (weighted by held-out steps).
    std::vector<Scores> mean(windows.size());
    for (size_t w = 0; w < windows.size(); ++w) {
      for (const Fold& f : folds) {
        const Scores& s = f.by_window[w];
        mean[w].crf += s.crf * static_cast<double>(s.steps);
        mean[w].hmm += s.hmm * static_cast<double>(s.steps);
        mean[w].steps += s.steps;
      }
      if (mean[w].steps > 0) {
        mean[w].crf /= static_cast<double>(mean[w].steps);
        mean[w].hmm /= static_cast<double>(mean[w].steps);
      }
    }
    if (!csv_path.empty()) {
      std::ofstream csv(csv_path);
      csv << "# " << note << "; corpus " << (paired ? ff->paired : ff->corpus)
          << (paired ? "; leave one recording out, mean over folds" : "; held out: " + ff->holdout + "*") << "\n";
      csv << "window,crf_ll_per_step,hmm_ll_per_step,steps,train_s\n";
      for (size_t w = 0; w < windows.size(); ++w) {
        double train_s = 0;
        for (const Fold& f : folds) train_s += f.train_s[w];
        csv << windows[w] << "," << mean[w].crf << "," << mean[w].hmm << "," << mean[w].steps << "," << train_s << "\n";
      }
      if (!csv) Fail(absl::FailedPreconditionError(kinemo::StrCat(csv_path, ": cannot write")));
    }
    if (!png_path.empty()) WritePlot(png_path, windows, mean, note);
    if (ff->json) {
      nlohmann::json j{{"corpus", paired ? ff->paired : ff->corpus}, {"pairing", note}, {"states", ff->states},
                       {"clusters", ff->clusters}, {"window", ff->window}, {"folds", nlohmann::json::array()}};
      const size_t wi = static_cast<size_t>(ff->window - 1);
      for (const Fold& f : folds) {
        nlohmann::json train = nlohmann::json::array(), by_window = nlohmann::json::array();
        for (const auto& s : f.train) train.push_back(s.name);
        for (size_t w = 0; w < windows.size(); ++w)
          by_window.push_back({{"window", windows[w]}, {"crf_ll_per_step", f.by_window[w].crf},
                               {"hmm_ll_per_step", f.by_window[w].hmm}, {"train_s", f.train_s[w]}});
        std::string test;
        for (const auto& s : f.test) test += (test.empty() ? "" : ",") + s.name;
        j["folds"].push_back({{"train", train}, {"test", test}, {"steps", f.by_window[wi].steps},
                              {"crf_ll_per_step", f.by_window[wi].crf}, {"hmm_ll_per_step", f.by_window[wi].hmm},
                              {"by_window", by_window}});
      }
      std::cout << j.dump() << "\n";
    } else if (!csv_path.empty() || !png_path.empty()) {
      std::cout << "wrote " << (csv_path.empty() ? "" : csv_path + " ") << (png_path.empty() ? "" : png_path + " ")
                << "— " << note << "\n";
    }
  });

  // --- bench ------------------------------------------------------------------
  struct BenchFlags {
    std::string root = "../shared/data", work = "/tmp/kinemo_crf_bench";
    std::vector<std::string> speech, gestures;
    bool json = false;
    double minutes = 12.0;
  };
  auto bf = std::make_shared<BenchFlags>();
  CLI::App* bench = crf->add_subcommand("bench", "Training time (25 states, 12 min) and online step latency");
  bench->add_option("--data-root", bf->root, "Where speech/ and motion/ are (default ../shared/data)");
  bench->add_option("--work-dir", bf->work, "Where the bench corpus is built");
  bench->add_option("--minutes", bf->minutes, "Minutes of training data (default 12)")->check(CLI::Range(0.05, 120.0));
  bench->add_option("--speech", bf->speech, "Speech files (default: all under DATA_ROOT/speech)");
  bench->add_option("--gestures", bf->gestures, "Gesture BVH clips (default: Bandai bye/byebye/call/guide/respond)");
  bench->add_flag("--json", bf->json, "Print {train_s_12min_25states, step_us_p50, step_us_p99}");
  bench->callback([bf] {
    std::vector<std::string> speech = bf->speech, gestures = bf->gestures;
    DefaultInputs(bf->root, &speech, &gestures);
    double total_s = 0;
    for (const auto& s : speech) {
      auto sp = OrFail(inference::ReadSpeechFile(s));
      total_s += static_cast<double>(sp.samples.size()) / sp.sample_rate_hz;
    }
    const int renditions = std::max(1, static_cast<int>(std::ceil(bf->minutes * 60.0 / total_s)));
    const std::string dir = (fs::path(bf->work) / "corpus").string();
    fs::remove_all(dir);
    OrFail(inference::BuildSyntheticCorpus({speech, gestures, dir, renditions, 7}));
    auto data = OrFail(inference::ImportPairedCorpus(dir));
    // Trim to the requested minutes of speech.
    std::vector<PairedSequence> train;
    double used = 0;
    for (auto& s : data) {
      if (used >= bf->minutes * 60.0) break;
      used += s.inputs.back().end_s - s.inputs.front().start_s;
      train.push_back(std::move(s));
    }
    ModelTrainParams p;  // 25 states, window 4, 10 clusters, 5 restarts
    inference::TrainReport report;
    const auto t0 = std::chrono::steady_clock::now();
    auto model = OrFail(inference::RemappedModel::Train(train, p, nullptr, &report));
    const double train_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // Online step latency over all steps (several passes).
    inference::OnlineFilter filter(model);
    std::vector<double> alpha(static_cast<size_t>(model.num_states()));
    std::vector<double> us;
    for (int pass = 0; pass < 5; ++pass) {
      for (const auto& seq : train) {
        filter.Reset();
        for (const auto& x : seq.inputs) {
          const auto a = std::chrono::steady_clock::now();
          filter.Push(x, alpha);
          const auto b = std::chrono::steady_clock::now();
          us.push_back(std::chrono::duration<double, std::micro>(b - a).count());
        }
      }
    }
    nlohmann::json j{{"train_s_12min_25states", train_s},
                     {"step_us_p50", Percentile(us, 0.5)},
                     {"step_us_p99", Percentile(us, 0.99)},
                     {"training_data_s", used},
                     {"training_steps", report.steps},
                     {"online_steps_timed", us.size()},
                     {"corpus", kinemo::StrCat(kCorpusNote, "; ", renditions,
                                               " renditions of the available speech")}};
    if (bf->json) std::cout << j.dump() << "\n";
    else std::cout << j.dump(2) << "\n";
  });
}

}  // namespace kinemo::cli
