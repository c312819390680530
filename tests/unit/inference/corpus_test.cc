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
