#include "services/inference/corpus/corpus.h"

#include <sndfile.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>

#include "common/motion/bvh.h"

namespace kinemo::inference {
namespace {

namespace fs = std::filesystem;

}  // namespace

Eigen::MatrixXd KinematicsOnSteps(const std::vector<gesture::KinematicSegment>& segments,
                                  const std::vector<ProsodyStep>& steps) {
  std::vector<double> mids;
  mids.reserve(steps.size());
  for (const auto& s : steps) mids.push_back(0.5 * (s.start_s + s.end_s));
  return gesture::KinematicsAtTimes(segments, mids);
}

StatusOr<Speech> ReadSpeechFile(const std::string& path) {
  SF_INFO info{};
  SNDFILE* f = sf_open(path.c_str(), SFM_READ, &info);
  if (f == nullptr) {
    if (!fs::exists(path)) return absl::NotFoundError(kinemo::StrCat(path, ": no such file"));
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": ", sf_strerror(nullptr)));
  }
  std::vector<float> inter(static_cast<size_t>(info.frames) * info.channels);
  const sf_count_t got = sf_readf_float(f, inter.data(), info.frames);
  sf_close(f);
  Speech s;
  s.sample_rate_hz = info.samplerate;
  s.samples.resize(static_cast<size_t>(got));
  for (sf_count_t i = 0; i < got; ++i) {
    double acc = 0;
    for (int c = 0; c < info.channels; ++c) acc += inter[static_cast<size_t>(i * info.channels + c)];
    s.samples[static_cast<size_t>(i)] = static_cast<float>(acc / info.channels);
  }
  return s;
}

StatusOr<std::vector<PairedRecording>> ImportPairedRecordings(const std::string& dir,
                                                             const ProsodyExtractor& extractor) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return absl::NotFoundError(kinemo::StrCat(dir, ": not a directory"));
  std::vector<fs::path> wavs;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (e.path().extension() == ".wav" && fs::exists(fs::path(e.path()).replace_extension(".bvh")))
      wavs.push_back(e.path());
  }
  std::sort(wavs.begin(), wavs.end());
  if (wavs.empty())
    return absl::NotFoundError(kinemo::StrCat(dir, ": no <name>.wav + <name>.bvh pair"));
  std::vector<PairedRecording> out;
  for (const auto& wav : wavs) {
    PairedRecording rec;
    rec.wav_path = wav.string();
    rec.bvh_path = fs::path(wav).replace_extension(".bvh").string();
    KINEMO_ASSIGN_OR_RETURN(Speech speech, ReadSpeechFile(rec.wav_path));
    rec.speech_s = static_cast<double>(speech.samples.size()) / std::max(1, speech.sample_rate_hz);
    auto track = extractor(speech.samples, speech.sample_rate_hz);
    if (!track.ok()) return Annotate(track.status(), rec.wav_path);
    KINEMO_ASSIGN_OR_RETURN(motion::Clip clip, motion::ReadBvhFile(rec.bvh_path));
    rec.motion_s = clip.duration_s();
    auto segs = gesture::ComputeKinematicSegments(clip);
    if (!segs.ok()) return Annotate(segs.status(), rec.bvh_path);
    PairedSequence& seq = rec.sequence;
    seq.name = wav.stem().string();
    // Steps beyond the end of the motion are dropped.
    for (const auto& s : track->steps) {
      if (0.5 * (s.start_s + s.end_s) <= clip.duration_s()) seq.inputs.push_back(s);
    }
    if (seq.inputs.empty()) return InvalidField(rec.wav_path, "no syllable inside the motion's duration");
    seq.outputs = KinematicsOnSteps(*segs, seq.inputs);
    const fs::path grid_path = fs::path(wav).replace_extension(".TextGrid");
    if (fs::exists(grid_path, ec)) {
      rec.textgrid_path = grid_path.string();
      KINEMO_ASSIGN_OR_RETURN(audio::TextGrid grid, audio::ReadTextGridFile(rec.textgrid_path));
      for (const char* name : {"words", "word"}) {
        if (const auto* tier = grid.FindTier(name); tier != nullptr && rec.words.empty())
          rec.words = audio::NonEmptyIntervals(*tier);
      }
      for (const char* name : {"phones", "phone"}) {
        if (const auto* tier = grid.FindTier(name); tier != nullptr && rec.phones.empty())
          rec.phones = audio::NonEmptyIntervals(*tier);
      }
    }
    out.push_back(std::move(rec));
  }
  return out;
}

StatusOr<std::vector<PairedSequence>> ImportPairedCorpus(const std::string& dir,
                                                         const ProsodyExtractor& extractor) {
  KINEMO_ASSIGN_OR_RETURN(std::vector<PairedRecording> recs, ImportPairedRecordings(dir, extractor));
  std::vector<PairedSequence> out;
  out.reserve(recs.size());
  for (auto& r : recs) out.push_back(std::move(r.sequence));
  return out;
}

// ---------------------------------------------------------------------------
// Synthetic pairing

namespace {

enum Tier { kSubdued = 0, kNeutral = 1, kEnergetic = 2 };

Tier TierOf(const std::string& name) {
  for (const char* w : {"_active_", "_angry_", "_happy_", "_childish_", "_chimpira_", "_proud_",
                        "_masculinity_"})
    if (name.find(w) != std::string::npos) return kEnergetic;
  for (const char* w : {"_sad_", "_tired_", "_old_", "_not-confident_", "_feminine_"})
    if (name.find(w) != std::string::npos) return kSubdued;
  return kNeutral;
}

struct Gesture {
  motion::Clip clip;
  int peak = 0;  // fastest hand frame
  Tier tier = kNeutral;
};

}  // namespace

StatusOr<SyntheticCorpusReport> BuildSyntheticCorpus(const SyntheticCorpusOptions& o) {
  if (o.speech_files.empty()) return InvalidField("speech_files", "empty");
  if (o.gesture_files.empty()) return InvalidField("gesture_files", "empty");
  if (o.renditions < 1) return InvalidField("renditions", o.renditions, " must be ≥ 1");
  std::vector<Gesture> gestures;
  for (const auto& path : o.gesture_files) {
    KINEMO_ASSIGN_OR_RETURN(motion::Clip clip, motion::ReadBvhFile(path));
    if (!gestures.empty() &&
        (clip.skeleton.num_channels() != gestures[0].clip.skeleton.num_channels() ||
         std::abs(clip.frame_time_s - gestures[0].clip.frame_time_s) > 1e-6))
      return InvalidField(path, "skeleton or frame time differs from ", o.gesture_files[0]);
    auto hands = gesture::ComputeHandTrack(clip);
    if (!hands.ok()) return Annotate(hands.status(), path);
    const Eigen::VectorXd speed = gesture::MeanHandSpeed(gesture::TimeDerivative(hands->p, hands->dt));
    Gesture g;
    speed.maxCoeff(&g.peak);
    g.tier = TierOf(fs::path(path).filename().string());
    g.clip = std::move(clip);
    gestures.push_back(std::move(g));
  }
  std::map<int, std::vector<int>> tiers;
  for (size_t k = 0; k < gestures.size(); ++k) tiers[gestures[k].tier].push_back(static_cast<int>(k));
  const motion::Clip& base = gestures[0].clip;
  const Eigen::RowVectorXd rest = base.frames.row(0);
  const double dt = base.frame_time_s;
  const int blend = std::max(1, static_cast<int>(std::lround(0.2 / dt)));
  // Root position channels stay at rest (no travelling).
  std::vector<int> root_pos;
  for (int c : base.skeleton.joint(0).position_column)
    if (c >= 0) root_pos.push_back(c);

  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) return absl::FailedPreconditionError(kinemo::StrCat(o.out_dir, ": ", ec.message()));
  SyntheticCorpusReport report;
  std::mt19937_64 rng(o.seed);
  for (const auto& speech_path : o.speech_files) {
    KINEMO_ASSIGN_OR_RETURN(Speech speech, ReadSpeechFile(speech_path));
    auto track = o.extractor(speech.samples, speech.sample_rate_hz);
    if (!track.ok()) return Annotate(track.status(), speech_path);
    const double duration = static_cast<double>(speech.samples.size()) / speech.sample_rate_hz;
    // Strength terciles.
    std::vector<double> strengths;
    for (const auto& a : track->accents) strengths.push_back(a.strength);
    std::sort(strengths.begin(), strengths.end());
    auto quantile = [&](double q) {
      return strengths.empty() ? 0.0 : strengths[static_cast<size_t>(q * (strengths.size() - 1))];
    };
    const double q1 = quantile(1.0 / 3), q2 = quantile(2.0 / 3);
    for (int r = 0; r < o.renditions; ++r) {
      motion::Clip out;
      out.skeleton = base.skeleton;
      out.frame_time_s = dt;
      const int frames = static_cast<int>(std::ceil(duration / dt)) + 1;
      out.frames = rest.replicate(frames, 1);
      int busy_until = -1;
      for (const auto& acc : track->accents) {
        Tier want = acc.strength >= q2 ? kEnergetic : (acc.strength >= q1 ? kNeutral : kSubdued);
        if (!tiers.count(want)) want = static_cast<Tier>(tiers.begin()->first);
        const auto& pool = tiers[want];
        const Gesture& g = gestures[pool[std::uniform_int_distribution<size_t>(0, pool.size() - 1)(rng)]];
        const double length_s = std::clamp(0.6 + 0.35 * acc.strength, 0.6, 1.8);
        const int before = static_cast<int>(0.4 * length_s / dt), after = static_cast<int>(0.6 * length_s / dt);
        const int src0 = std::max(0, g.peak - before);
        const int src1 = std::min(g.clip.num_frames() - 1, g.peak + after);
        const double lead_s = std::uniform_real_distribution<double>(0.03, 0.22)(rng);
        const int dst_peak = static_cast<int>(std::lround((acc.time_s - lead_s) / dt));
        const int dst0 = dst_peak - (g.peak - src0);
        if (dst0 <= busy_until || dst0 < 0 || dst0 + (src1 - src0) >= frames) continue;
        const int len = src1 - src0 + 1;
        for (int k = 0; k < len; ++k) {
          const double w = std::min({1.0, (k + 1.0) / blend, (len - k) / static_cast<double>(blend)});
          Eigen::RowVectorXd target = g.clip.frames.row(src0 + k);
          for (Eigen::Index c = 0; c < target.size(); ++c) {
            // Unwrap angles towards the rest value before blending.
            while (target(c) - rest(c) > 180.0) target(c) -= 360.0;
            while (target(c) - rest(c) < -180.0) target(c) += 360.0;
          }
          for (int c : root_pos) target(c) = rest(c);
          out.frames.row(dst0 + k) = (1.0 - w) * rest + w * target;
        }
        busy_until = dst0 + len;
        ++report.gestures_placed;
      }
      const std::string stem =
          kinemo::StrCat(fs::path(speech_path).stem().string(), "_r", r);
      const fs::path dir(o.out_dir);
      fs::copy_file(speech_path, dir / (stem + ".wav"), fs::copy_options::overwrite_existing, ec);
      if (ec) return absl::InternalError(kinemo::StrCat(speech_path, ": copy failed: ", ec.message()));
      KINEMO_RETURN_IF_ERROR(motion::WriteBvhFile(out, (dir / (stem + ".bvh")).string()));
      ++report.recordings;
      report.speech_s += duration;
    }
  }
  std::ofstream readme(fs::path(o.out_dir) / "README.txt");
  readme << "SYNTHETIC PAIRING - not a recorded speech+motion corpus.\n"
            "Built by kinemo's BuildSyntheticCorpus (seed " << o.seed << ", " << o.renditions
         << " rendition(s) per speech file) from real speech and real motion capture that were\n"
            "NOT recorded together: each <name>.bvh is a rest pose with real gesture excerpts placed\n"
            "at the accents detected in <name>.wav (stroke 0.03-0.22 s before the accent, length\n"
            "growing with accent strength, energy tier of the clip chosen by strength).\n"
            "Speech files:\n";
  for (const auto& s : o.speech_files) readme << "  " << s << "\n";
  readme << "Gesture clips:\n";
  for (const auto& s : o.gesture_files) readme << "  " << s << "\n";
  return report;
}

}  // namespace kinemo::inference
