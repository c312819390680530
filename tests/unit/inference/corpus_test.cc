// The paired-corpus pipeline on real files from tests/data only: prosody
// features of real speech, kinematic parameters of real motion capture, a
// small synthetic pairing of the two (speech and motion were NOT recorded
// together), import, and a small model trained on it.
#include "services/inference/corpus/corpus.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "common/motion/bvh.h"

namespace kinemo::inference {
namespace {

namespace fs = std::filesystem;

const std::string kData = KINEMO_TEST_DATA_DIR;
const std::string kSpeech1 = kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav";
const std::string kSpeech2 = kData + "/speech/sense_and_sensibility_01_austen_64kb-0930.wav";
const std::string kGesture = kData + "/motion/dataset-1_bye_normal_001.bvh";

TEST(ProsodyFeaturesTest, RealSpeechGivesSyllableSteps) {
  auto speech = ReadSpeechFile(kSpeech1);
  ASSERT_TRUE(speech.ok()) << speech.status();
  EXPECT_EQ(speech->sample_rate_hz, 16000);
  auto track = ExtractProsody(speech->samples, speech->sample_rate_hz);
  ASSERT_TRUE(track.ok()) << track.status();
  const double duration = static_cast<double>(speech->samples.size()) / speech->sample_rate_hz;
  // "he was not an ill disposed young man": 9 syllables in 3 s.
  int voiced = 0;
  double covered = 0;
  for (const auto& s : track->steps) {
    EXPECT_TRUE(ValidateProsodyStep(s, "step").ok());
    covered += s.length_s;
    if (s.voiced) {
      ++voiced;
      EXPECT_GT(s.f0_mean_hz, 70);
      EXPECT_LT(s.f0_mean_hz, 300);
    }
  }
  EXPECT_GE(voiced, 4);
  EXPECT_LE(voiced, 16);
  EXPECT_NEAR(covered, duration, 0.1);
  for (const auto& a : track->accents) {
    EXPECT_GT(a.strength, 0.5);
    EXPECT_TRUE(track->steps[a.step].voiced);
  }
  std::cout << track->steps.size() << " steps, " << voiced << " voiced, " << track->accents.size()
            << " accents\n";
}

TEST(KinematicsTest, RealGestureHasActiveAndRestingSegments) {
  auto clip = motion::ReadBvhFile(kGesture);
  ASSERT_TRUE(clip.ok()) << clip.status();
  auto segs = gesture::ComputeKinematicSegments(*clip);
  ASSERT_TRUE(segs.ok()) << segs.status();
  ASSERT_GE(segs->size(), 2u);
  double vmin = 1e9, vmax = -1e9;
  for (const auto& s : *segs) {
    EXPECT_TRUE(s.params.allFinite());
    EXPECT_GT(s.end_s, s.start_s);
    vmin = std::min(vmin, s.params(2));
    vmax = std::max(vmax, s.params(2));
  }
  EXPECT_GT(vmax - vmin, 1.0) << "velocity should differ between stroke and hold (log scale)";
  EXPECT_NEAR(segs->back().end_s, clip->duration_s(), 1e-9);
}

TEST(CorpusTest, SyntheticPairingImportsAndTrains) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("kinemo_corpus_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  SyntheticCorpusOptions o;
  o.speech_files = {kSpeech1, kSpeech2};
  o.gesture_files = {kGesture};
  o.out_dir = dir.string();
  o.renditions = 3;
  auto report = BuildSyntheticCorpus(o);
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_EQ(report->recordings, 6);
  EXPECT_GT(report->gestures_placed, 0);
  std::ifstream readme(dir / "README.txt");
  std::string first;
  std::getline(readme, first);
  EXPECT_NE(first.find("SYNTHETIC PAIRING"), std::string::npos);

  auto data = ImportPairedCorpus(dir.string());
  ASSERT_TRUE(data.ok()) << data.status();
  ASSERT_EQ(data->size(), 6u);
  std::size_t steps = 0;
  for (const auto& s : *data) {
    EXPECT_TRUE(ValidatePairedSequence(s, s.name).ok());
    steps += s.inputs.size();
  }
  EXPECT_GT(steps, 30u);
  ModelTrainParams p;
  p.num_states = 3;
  p.window = 2;
  p.num_clusters = 3;
  p.hmm_restarts = 2;
  auto model = RemappedModel::Train(*data, p, nullptr, nullptr);
  ASSERT_TRUE(model.ok()) << model.status();
  auto sc = model->Evaluate((*data)[0]);
  ASSERT_TRUE(sc.ok());
  EXPECT_TRUE(std::isfinite(sc->crf_ll_per_step));
  EXPECT_TRUE(std::isfinite(sc->hmm_ll_per_step));
  fs::remove_all(dir);
}

TEST(CorpusTest, ErrorsNameThePath) {
  EXPECT_EQ(ImportPairedCorpus("/nonexistent/dir").status().code(), absl::StatusCode::kNotFound);
  const fs::path empty = fs::path(::testing::TempDir()) / ("kinemo_empty_" + std::to_string(::getpid()));
  fs::create_directories(empty);
  auto st = ImportPairedCorpus(empty.string()).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kNotFound);
  EXPECT_NE(st.message().find("no <name>.wav + <name>.bvh pair"), std::string::npos);
  fs::remove_all(empty);
  EXPECT_EQ(ReadSpeechFile("/nonexistent.wav").status().code(), absl::StatusCode::kNotFound);
  std::vector<float> nan_samples(1600, 0.0f);
  nan_samples[5] = std::nanf("");
  EXPECT_EQ(ExtractProsody(nan_samples, 16000).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace kinemo::inference

namespace kinemo::inference {
namespace {

// BEAT2: speech and motion recorded together, with word and phone alignments.
TEST(PairedRecordingsTest, Beat2TakesImportWithTheirTextGrids) {
  auto recs = ImportPairedRecordings(kData + "/paired/beat2");
  ASSERT_TRUE(recs.ok()) << recs.status();
  ASSERT_EQ(recs->size(), 2u);
  const PairedRecording& a = (*recs)[0];
  const PairedRecording& b = (*recs)[1];
  EXPECT_EQ(a.sequence.name, "2_scott_0_1_1");
  EXPECT_EQ(b.sequence.name, "2_scott_0_2_2");
  EXPECT_NEAR(a.speech_s, 64.10, 0.01);
  EXPECT_NEAR(b.speech_s, 62.0, 0.05);
  EXPECT_NEAR(b.motion_s, 1804 / 30.0, 0.05);
  for (const PairedRecording* r : {&a, &b}) {
    SCOPED_TRACE(r->sequence.name);
    EXPECT_FALSE(r->textgrid_path.empty());
    // A minute of free speech: one to five syllable steps a second.
    EXPECT_GT(r->sequence.inputs.size(), 60u);
    EXPECT_LT(r->sequence.inputs.size(), 400u);
    ASSERT_EQ(r->sequence.outputs.rows(), static_cast<Eigen::Index>(r->sequence.inputs.size()));
    EXPECT_TRUE(ValidatePairedSequence(r->sequence, "sequence").ok());
    // Steps end with the capture (take 2's capture stops ~1.9 s before its audio).
    const auto& last = r->sequence.inputs.back();
    EXPECT_LE(0.5 * (last.start_s + last.end_s), r->motion_s + 1e-9);
    // Words and phones from the TextGrid, silences left out, in time order.
    EXPECT_GT(r->words.size(), 100u);
    EXPECT_GT(r->phones.size(), 2 * r->words.size());
    for (size_t i = 1; i < r->words.size(); ++i) EXPECT_GE(r->words[i].start_s, r->words[i - 1].end_s - 1e-9);
    for (const auto& w : r->words) EXPECT_FALSE(w.text.empty());
    // The aligned speech lies inside the recording, and the detected syllable
    // steps cover it: voiced steps fall mostly inside words.
    EXPECT_LE(r->words.back().end_s, r->speech_s + 1e-6);
    int voiced = 0, inside = 0;
    for (const auto& s : r->sequence.inputs) {
      if (!s.voiced) continue;
      ++voiced;
      const double mid = 0.5 * (s.start_s + s.end_s);
      for (const auto& w : r->words) {
        if (mid >= w.start_s - 0.05 && mid <= w.end_s + 0.05) {
          ++inside;
          break;
        }
      }
    }
    ASSERT_GT(voiced, 0);
    EXPECT_GT(static_cast<double>(inside) / voiced, 0.8) << inside << " of " << voiced;
  }
  // The kinematic parameters differ over time (real gestures, not a still pose).
  const Eigen::VectorXd v = a.sequence.outputs.col(2);  // V: log mean hand speed
  EXPECT_GT(v.maxCoeff() - v.minCoeff(), 1.0);
}

// Pauses reach the model as the coordinator sends them: unvoiced, 0 dB.
TEST(PairedRecordingsTest, PauseStepsAreUnvoicedWithoutIntensity) {
  auto speech = ReadSpeechFile(kData + "/paired/beat2/2_scott_0_2_2.wav");
  ASSERT_TRUE(speech.ok());
  auto track = ExtractProsodyWithProsodyCore(speech->samples, speech->sample_rate_hz);
  ASSERT_TRUE(track.ok()) << track.status();
  int pauses = 0;
  for (const auto& s : track->steps) {
    EXPECT_TRUE(ValidateProsodyStep(s, "step").ok());
    if (s.intensity_mean_db == 0.0) {
      EXPECT_FALSE(s.voiced);
      EXPECT_LE(s.length_s, 0.5 + 1e-9);
      ++pauses;
    }
  }
  EXPECT_GT(pauses, 5);
}

}  // namespace
}  // namespace kinemo::inference
