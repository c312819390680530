// The face model (docs/face.md): training and its leave-one-take-out judge.
//
//   kinemo face train --corpus DIR [--take NAME]... (--out MODEL.json |
//                     --store DIR [--id bundled] [--overwrite]) [--description T] [--json]
//       Trains the face model on paired takes (<name>.wav + <name>.bvh whose
//       SMPL-X `jaw` joint is the captured face + <name>.TextGrid with a
//       phones tier): the jaw opening by ridge regression, the mouth-shape
//       classes by linear discriminants, both on MFCC context windows. --out
//       writes the model file; --store commits it to an artifact store as
//       face_models/<id>/<version>/face_model.json (the prosody service's).
//   kinemo face loto --corpus DIR [--peers DIR] [--compare NAME=TAKE:FILE.bvh]... [--json]
//       Leave one take out: per fold, train on one take and judge the other
//       take's face, offline and live (20 ms chunks through the live path),
//       against its captured jaw (Pearson r frame by frame, beside the other
//       take's real jaw, the loudness envelope, and any --compare BVH such as
//       the library-copied jaw or the peer MambaTalk on 2_2, read from
//       --peers when present) and its forced-aligned phones (dominant thesis
//       category per speech frame, chance beside; B/P/M frames with the lips
//       closed; pauses with the mouth at rest), and the vowel shapes as a rig
//       draws them (retarget::FaceInputs: the vowel visemes' weights opened
//       with the jaw) against the captured jaw: vowel_opening_r (beside
//       vowel_weight_r, the vowels' weights alone), and their median in
//       vowel frames (and the weights') beside the captured jaw's, relative
//       to the speaker's wide opening (face::kSmplxJawSpeechWideDeg).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "common/audio/textgrid.h"
#include "common/face/face_compose.h"
#include "common/face/jaw.h"
#include "common/face/viseme_scores.h"
#include "common/face/visemes.h"
#include "common/motion/bvh.h"
#include "common/motion/motion_check.h"
#include "common/retarget/face_map.h"
#include "common/store/artifact_store.h"
#include "services/cli/commands.h"
#include "services/prosody/core/face_corpus.h"
#include "services/prosody/core/face_model.h"
#ifdef KINEMO_WITH_SPHINX
#include "services/prosody/core/recognizer.h"
#endif

namespace kinemo::cli {
namespace {
namespace cmd_face {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;
using Json = nlohmann::json;

[[noreturn]] void Fail(std::string_view cmd, const absl::Status& status) {
  FailCommand(cmd, status, {absl::StatusCode::kInvalidArgument, absl::StatusCode::kNotFound,
                            absl::StatusCode::kFailedPrecondition, absl::StatusCode::kAlreadyExists});
}

using prosody::FaceTakeNames;
using prosody::ReadFaceTake;

double Pearson(const std::vector<double>& a, const std::vector<double>& b) {
  const std::size_t n = std::min(a.size(), b.size());
  if (n < 2) return 0;
  double ma = 0, mb = 0;
  for (std::size_t i = 0; i < n; ++i) {
    ma += a[i];
    mb += b[i];
  }
  ma /= static_cast<double>(n);
  mb /= static_cast<double>(n);
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 0.0;
}

// The face of a take on its capture's clock (speech face -> composer).
face::FaceTrack Compose(const std::vector<face::SpeechFaceFrame>& speech, double frame_time_s, std::size_t frames) {
  return face::ComposeTrack(speech, {}, face::Expression::kNeutral, 0, frame_time_s,
                            frames > 0 ? static_cast<double>(frames - 1) * frame_time_s : 0.0);
}

// Per frame of `track`, the reference phone's class (TextGrid) at its time.
std::vector<int> ReferenceClasses(const prosody::FaceTrainingTake& take, const face::FaceTrack& track) {
  std::vector<int> out(track.frames.size(), static_cast<int>(face::PhoneClass::kSil));
  std::size_t p = 0;
  for (std::size_t i = 0; i < track.frames.size(); ++i) {
    const double t = track.frames[i].time_s;
    while (p < take.phones.size() && take.phones[p].end_s <= t) ++p;
    face::PhoneClass c = face::PhoneClass::kSil;
    if (p < take.phones.size() && take.phones[p].start_s <= t) (void)face::PhoneToClass(take.phones[p].phone, &c);
    out[i] = static_cast<int>(c);
  }
  return out;
}

// The visemes of `track` against the take's forced alignment
// (common/face/viseme_scores.h); KINEMO_FACE_DIAG: what the B/P/M frames were
// shown as, on stderr.
face::VisemeScores ScoreVisemes(const prosody::FaceTrainingTake& take, const face::FaceTrack& track) {
  const std::vector<int> ref = ReferenceClasses(take, track);
  if (std::getenv("KINEMO_FACE_DIAG")) {
    std::array<int, face::kNumCategories> bpm_as{};
    for (std::size_t i = 0; i < ref.size(); ++i) {
      if (face::kClassCategory[ref[i]] == face::Category::kBPM) ++bpm_as[face::Dominant(track.frames[i].categories)];
    }
    std::fprintf(stderr, "  B/P/M frames shown as:");
    for (int c = 0; c < face::kNumCategories; ++c) {
      if (bpm_as[c] > 0) std::fprintf(stderr, " %s %d", std::string(face::kCategoryNames[c]).c_str(), bpm_as[c]);
    }
    std::fprintf(stderr, "\n");
  }
  return face::ScoreVisemes(ref, track);
}

// The loudness envelope (dB of the RMS over 25 ms) at each capture frame.
std::vector<double> Loudness(const std::vector<float>& samples, double frame_time_s, std::size_t frames) {
  std::vector<double> out(frames);
  for (std::size_t i = 0; i < frames; ++i) {
    const long c = std::lround(static_cast<double>(i) * frame_time_s * prosody::kFaceSampleRateHz);
    double e = 1e-10;
    for (long k = c - 200; k < c + 200; ++k) {
      if (k >= 0 && k < static_cast<long>(samples.size())) e += static_cast<double>(samples[k]) * samples[k];
    }
    out[i] = 10 * std::log10(e / 400);
  }
  return out;
}

struct TrainArgs {
  std::string corpus, out, store, id = "bundled", description;
  std::vector<std::string> takes;
  bool overwrite = false, json = false;
};

struct LotoArgs {
  std::string corpus, peers;
  std::vector<std::string> compare;
  bool json = false;
  double chunk_ms = 20;
};

void RunTrain(const TrainArgs& a) {
  const std::string cmd = "face train";
  std::vector<std::string> names = a.takes.empty() ? FaceTakeNames(a.corpus) : a.takes;
  if (names.empty()) Fail(cmd, InvalidField("--corpus", a.corpus, ": no takes (<name>.wav + .bvh + .TextGrid)"));
  std::vector<prosody::FaceTrainingTake> takes;
  for (const auto& n : names) {
    auto t = ReadFaceTake(a.corpus, n);
    if (!t.ok()) Fail(cmd, t.status());
    takes.push_back(*std::move(t));
  }
  auto model = prosody::TrainFaceModel(takes, {});
  if (!model.ok()) Fail(cmd, model.status());
  model->description = a.description.empty()
                           ? kinemo::StrCat("face model trained on ", names.size(), " take(s) of ", fs::path(a.corpus).filename().string())
                           : a.description;
  const std::string text = prosody::FaceModelToJson(*model);
  Json out = {{"takes", names}, {"training_s", model->training_s}};
  if (!a.out.empty()) {
    std::ofstream(a.out) << text;
    out["out"] = a.out;
  } else {
    auto store = store::ArtifactStore::Open(a.store, "--store");
    if (!store.ok()) Fail(cmd, store.status());
    auto draft = (*store)->Begin("face_models", a.id);
    if (!draft.ok()) Fail(cmd, Annotate(draft.status(), "--id"));
    if (Status s = draft->WriteFile("face_model.json", text); !s.ok()) Fail(cmd, s);
    store::ArtifactMeta meta;
    meta.description = model->description;
    meta.summary_json = Json({{"takes", names}, {"training_s", model->training_s}}).dump();
    auto committed = (*store)->Commit(*std::move(draft), meta, a.overwrite);
    if (!committed.ok()) Fail(cmd, Annotate(committed.status(), "--id"));
    out["artifact"] = store::RefString(committed->ref());
  }
  if (a.json) {
    std::printf("%s\n", out.dump().c_str());
  } else {
    std::printf("face model: %zu take(s), %.1f s of speech -> %s\n", names.size(), model->training_s,
                a.out.empty() ? out["artifact"].get<std::string>().c_str() : a.out.c_str());
  }
}

void RunLoto(const LotoArgs& a) {
  const std::string cmd = "face loto";
  const std::vector<std::string> names = FaceTakeNames(a.corpus);
  if (names.size() != 2) Fail(cmd, InvalidField("--corpus", "needs two takes, found ", names.size()));
  std::vector<prosody::FaceTrainingTake> takes;
  for (const auto& n : names) {
    auto t = ReadFaceTake(a.corpus, n);
    if (!t.ok()) Fail(cmd, t.status());
    takes.push_back(*std::move(t));
  }
  // Extra jaw rows: NAME=TAKE:FILE.bvh, and the peer on 2_2 when present.
  struct Extra {
    std::string name, take, file;
  };
  std::vector<Extra> extras;
  for (const std::string& c : a.compare) {
    const auto eq = c.find('='), colon = c.find(':', eq == std::string::npos ? 0 : eq);
    if (eq == std::string::npos || colon == std::string::npos) Fail(cmd, InvalidField("--compare", "'", c, "' is not NAME=TAKE:FILE.bvh"));
    extras.push_back({c.substr(0, eq), c.substr(eq + 1, colon - eq - 1), c.substr(colon + 1)});
  }
  const fs::path peer = fs::path(a.peers) / "mambatalk_2_scott_0_2_2.bvh";
  const bool peer_present = !a.peers.empty() && fs::exists(peer);
  if (peer_present) extras.push_back({"MambaTalk (peer)", "2_scott_0_2_2", peer.string()});
  // The recogniser's phones of each take (words found, force-aligned: what
  // Animate with visemes uses), when it is built in.
  std::vector<std::vector<prosody::FacePhone>> recognized(takes.size());
  bool recognizer_ran = false;
#ifdef KINEMO_WITH_SPHINX
  if (auto rec = prosody::SphinxRecognizer::Create({}); rec.ok()) {
    for (std::size_t t = 0; t < takes.size(); ++t) {
      auto both = (*rec)->Recognize(takes[t].samples);
      if (!both.ok()) Fail(cmd, both.status());
      for (const auto& p : both->phones) recognized[t].push_back({p.start_s, p.end_s, p.phone});
    }
    recognizer_ran = true;
  }
#endif
  Json folds = Json::array();
  for (int fold = 0; fold < 2; ++fold) {
    const prosody::FaceTrainingTake& train = takes[fold];
    const prosody::FaceTrainingTake& test = takes[1 - fold];
    prosody::FaceTrainOptions options;
    if (const char* o = std::getenv("KINEMO_FACE_TRAIN")) {  // tuning: key=value,...
      for (const std::string& kv : SplitList(o)) {
        const auto eq = kv.find('=');
        const std::string k = kv.substr(0, eq);
        const double v = std::stod(kv.substr(eq + 1));
        if (k == "prior_power") options.prior_power = v;
        else if (k == "score_scale") options.score_scale = v;
        else if (k == "live_running_cmn") options.live_running_cmn = v != 0;
        else if (k == "stay") options.stay = v;
        else if (k == "class_shrink") options.class_shrink = v;
        else if (k == "jaw_smooth") options.jaw_smooth = v;
        else if (k == "min_closure_s") options.min_closure_s = v;
        else if (k == "live_min_closure_s") options.live_min_closure_s = v;
        else if (k == "bpm_prior_power") options.bpm_prior_power = v;
        else Fail(cmd, InvalidField("KINEMO_FACE_TRAIN", "unknown ", k));
      }
    }
    auto model = prosody::TrainFaceModel(std::span(&train, 1), options);
    if (!model.ok()) Fail(cmd, model.status());
    auto shared = std::make_shared<const prosody::FaceModel>(*model);
    const std::size_t frames = test.jaw_open_deg.size();
    const double ft = test.jaw_frame_time_s;
    const face::FaceTrack offline = Compose(prosody::AnalyzeFace(test.samples, *model), ft, frames);
    const face::FaceTrack live = Compose(prosody::AnalyzeFaceLive(test.samples, shared, a.chunk_ms / 1000), ft, frames);
    std::vector<std::pair<std::string, face::FaceTrack>> rows = {{"offline", offline}, {"live", live}};
    if (recognizer_ran) {
      const auto& phones = recognized[1 - fold];
      rows.push_back({"offline + recogniser phones", Compose(prosody::AnalyzeFace(test.samples, *model, phones), ft, frames)});
      if (const char* w = std::getenv("KINEMO_FACE_PHONE_WEIGHTS")) {  // tuning
        for (const std::string& x : SplitList(w)) {
          rows.push_back({"offline + phones w=" + x, Compose(prosody::AnalyzeFace(test.samples, *model, phones, std::stod(x)), ft, frames)});
        }
      }
      if (const char* w = std::getenv("KINEMO_FACE_PHONE_DELAYS")) {  // tuning
        for (const std::string& x : SplitList(w)) {
          rows.push_back({"offline + phones delay=" + x,
                          Compose(prosody::AnalyzeFace(test.samples, *model, phones, 1000, std::stod(x) / 1000), ft, frames)});
        }
      }
      // Today's visemes: the recogniser's phones alone (Table 4.5).
      std::vector<face::SpeechFaceFrame> only;
      const int n = static_cast<int>(test.samples.size() / 160) + 1;
      std::size_t p = 0;
      for (int k = 0; k < n; ++k) {
        face::SpeechFaceFrame f;
        f.time_s = k * prosody::kFaceStepS;
        while (p < phones.size() && phones[p].end_s <= f.time_s) ++p;
        face::PhoneClass c = face::PhoneClass::kSil;
        if (p < phones.size() && phones[p].start_s <= f.time_s) (void)face::PhoneToClass(phones[p].phone, &c);
        f.classes[static_cast<int>(c)] = 1;
        only.push_back(f);
      }
      face::FaceTrack alone = Compose(only, ft, frames);
      for (face::FaceFrame& f : alone.frames) f.jaw_known = false;  // phones carry no jaw
      rows.push_back({"recogniser phones alone (before)", std::move(alone)});
      if (std::getenv("KINEMO_FACE_SHIFT")) {
        for (int take = 0; take < 2; ++take) {
          for (int shift_ms = -60; shift_ms <= 60; shift_ms += 10) {
            std::vector<face::SpeechFaceFrame> sh;
            const auto& ph = recognized[take];
            const int nn = static_cast<int>(takes[take].samples.size() / 160) + 1;
            std::size_t q = 0;
            for (int k = 0; k < nn; ++k) {
              face::SpeechFaceFrame f;
              f.time_s = k * prosody::kFaceStepS;
              const double t = f.time_s - shift_ms / 1000.0;
              while (q < ph.size() && ph[q].end_s <= t) ++q;
              face::PhoneClass c = face::PhoneClass::kSil;
              if (q < ph.size() && ph[q].start_s <= t) (void)face::PhoneToClass(ph[q].phone, &c);
              f.classes[static_cast<int>(c)] = 1;
              sh.push_back(f);
            }
            const face::VisemeScores s = ScoreVisemes(takes[take], Compose(sh, takes[take].jaw_frame_time_s, takes[take].jaw_open_deg.size()));
            std::fprintf(stderr, "take %d shift %+d ms: acc %.3f bpm %.3f\n", take, shift_ms, s.accuracy, s.bpm_closed);
          }
        }
      }
    }
    auto jaw_of = [](const face::FaceTrack& t) {
      std::vector<double> v;
      for (const auto& f : t.frames) v.push_back(f.jaw_open_deg);
      return v;
    };
    Json jaw = Json::object();
    jaw["kinemo offline"] = Pearson(jaw_of(offline), test.jaw_open_deg);
    if (rows.size() > 2) jaw["kinemo offline + recogniser phones"] = Pearson(jaw_of(rows[2].second), test.jaw_open_deg);
    jaw["kinemo live"] = Pearson(jaw_of(live), test.jaw_open_deg);
    jaw["jaw of other speech"] = Pearson(train.jaw_open_deg, test.jaw_open_deg);
    jaw["loudness alone"] = Pearson(Loudness(test.samples, ft, frames), test.jaw_open_deg);
    for (const Extra& e : extras) {
      if (e.take != test.name) continue;
      double eft = 0;
      auto v = prosody::ReadJawOpenings(e.file, &eft);
      if (!v.ok()) Fail(cmd, Annotate(v.status(), "--compare"));
      jaw[e.name] = Pearson(*v, test.jaw_open_deg);
    }
    Json vis = Json::object();
    for (const auto& [name, track] : rows) {
      const face::VisemeScores s = ScoreVisemes(test, track);
      // The vowels as a rig draws them: their inputs summed, and in frames
      // where vowels dominate, beside the captured jaw on the same scale.
      std::vector<double> drawn, raw, drawn_in, raw_in, captured_in;
      for (std::size_t k = 0; k < track.frames.size() && k < test.jaw_open_deg.size(); ++k) {
        std::array<float, retarget::kNumFaceInputs> in;
        retarget::FaceInputs(track.frames[k], in);
        double v = 0, weight = 0;
        for (face::OvrViseme o : retarget::kVowelVisemes) {
          v += in[static_cast<size_t>(o)];
          weight += track.frames[k].ovr[static_cast<size_t>(o)];
        }
        drawn.push_back(v);
        raw.push_back(weight);
        if (weight > 0.5) {
          drawn_in.push_back(v);
          raw_in.push_back(weight);
          captured_in.push_back(std::clamp(test.jaw_open_deg[k] / face::kSmplxJawSpeechWideDeg, 0.0, 1.0));
        }
      }
      std::vector<double> captured(test.jaw_open_deg.begin(), test.jaw_open_deg.begin() + static_cast<std::ptrdiff_t>(drawn.size()));
      vis[name] = {{"vowel_opening_r", Pearson(drawn, captured)},
                   {"vowel_weight_r", Pearson(raw, captured)},
                   {"vowel_opening_median", motion::Quantile(drawn_in, 0.5)},
                   {"vowel_weight_median", motion::Quantile(raw_in, 0.5)},
                   {"captured_jaw_median_in_vowels", motion::Quantile(captured_in, 0.5)},
                   {"accuracy", s.accuracy}, {"chance", s.chance}, {"bpm_closed", s.bpm_closed},
                   {"pauses_at_rest", s.pauses_at_rest}, {"closed_outside_bpm", s.closed_outside_bpm},
                   {"bpm_phones_closed", s.bpm_phones_closed}, {"bpm_phones", s.bpm_phones},
                   {"closures", s.closures}, {"spurious_closures_per_min", s.spurious_closures_per_min},
                   {"speech_frames", s.speech_frames},
                   {"bpm_frames", s.bpm_frames}, {"pause_frames", s.pause_frames}};
    }
    folds.push_back({{"train", train.name}, {"judge", test.name}, {"jaw_r", jaw}, {"visemes", vis}});
  }
  if (a.json) {
    std::printf("%s\n", Json({{"folds", folds}, {"peer_present", peer_present}}).dump().c_str());
    return;
  }
  for (const Json& f : folds) {
    std::printf("train %s, judge %s\n  jaw: Pearson r with the captured jaw, frame by frame\n", f["train"].get<std::string>().c_str(),
                f["judge"].get<std::string>().c_str());
    for (const auto& [k, v] : f["jaw_r"].items()) std::printf("    %-28s %6.3f\n", k.c_str(), v.get<double>());
    std::printf(
        "  visemes vs forced-aligned phones   accuracy  chance  B/P/M closed  pauses at rest  closed elsewhere"
        "  b/p/m phones closed  spurious closures/min\n");
    for (const auto& [k, v] : f["visemes"].items()) {
      std::printf("    %-30s %6.3f  %6.3f  %12.3f  %14.3f  %16.3f  %19.3f  %21.1f\n", k.c_str(), v["accuracy"].get<double>(),
                  v["chance"].get<double>(), v["bpm_closed"].get<double>(), v["pauses_at_rest"].get<double>(),
                  v["closed_outside_bpm"].get<double>(), v["bpm_phones_closed"].get<double>(),
                  v["spurious_closures_per_min"].get<double>());
    }
  }
  if (!peer_present) std::printf("MambaTalk (peer): absent (%s not found)\n", peer.string().c_str());
}

}  // namespace cmd_face
}  // namespace

void RegisterFaceCommands(CLI::App& app) {
  using namespace cmd_face;
  auto* face = app.add_subcommand("face", "The face model: train it on paired takes, judge it leave-one-take-out");
  face->require_subcommand(1);
  auto* train = face->add_subcommand("train", "Train the face model (jaw, mouth shapes) on paired takes");
  auto t = std::make_shared<TrainArgs>();
  train->add_option("--corpus", t->corpus, "folder of <name>.wav + <name>.bvh (SMPL-X jaw) + <name>.TextGrid (phones)")
      ->required();
  train->add_option("--take", t->takes, "train on this take only (repeatable; default every take)");
  train->add_option("-o,--out", t->out, "write the model file here");
  train->add_option("--store", t->store, "commit the model to this artifact store (face_models/<id>/<version>)");
  train->add_option("--id", t->id, "the model's id in --store")->capture_default_str();
  train->add_flag("--overwrite", t->overwrite, "with --store: a new version of an existing id");
  train->add_option("--description", t->description, "the artifact's description");
  train->add_flag("--json", t->json, "print {takes, training_s, out|artifact}");
  train->callback([t] {
    if (t->out.empty() == t->store.empty()) {
      std::cerr << "kinemo face train: give one of -o/--out and --store\n";
      throw CliExit{2};
    }
    RunTrain(*t);
  });
  auto* loto = face->add_subcommand("loto", "Judge the face model leave-one-take-out against the captured face");
  auto l = std::make_shared<LotoArgs>();
  loto->add_option("--corpus", l->corpus, "folder with the two paired takes")->required();
  loto->add_option("--peers", l->peers, "folder with mambatalk_2_scott_0_2_2.bvh (the peer row; absent = said so)");
  loto->add_option("--compare", l->compare, "another jaw row: NAME=TAKE:FILE.bvh (e.g. today's library-copied jaw)");
  loto->add_option("--chunk-ms", l->chunk_ms, "live chunk length")->capture_default_str();
  loto->add_flag("--json", l->json, "print {folds: [{train, judge, jaw_r, visemes}], peer_present}");
  loto->callback([l] { RunLoto(*l); });
}

}  // namespace kinemo::cli
