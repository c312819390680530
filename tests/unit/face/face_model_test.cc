// The face model on the real paired takes of tests/data/paired/beat2 (speech
// recorded with the captured face): trained on one take, it must predict the
// other take's jaw better than that take's jaw predicts it (the other-speech
// baseline), place the thesis categories above chance, and run live without
// waiting for audio past a chunk. Blinks on a real clip come at a plausible
// rate. (The full table, offline and live per fold: `kinemo face loto`.)
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "common/face/face_compose.h"
#include "common/face/visemes.h"
#include "services/prosody/core/face_corpus.h"
#include "services/prosody/core/face_model.h"

namespace kinemo::prosody {
namespace {

const std::string kBeat2 = std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2";

double Pearson(const std::vector<double>& a, const std::vector<double>& b) {
  const std::size_t n = std::min(a.size(), b.size());
  double ma = 0, mb = 0;
  for (std::size_t i = 0; i < n; ++i) ma += a[i], mb += b[i];
  ma /= n, mb /= n;
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return sab / std::sqrt(saa * sbb);
}

class FaceModelBeat2 : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto a = ReadFaceTake(kBeat2, "2_scott_0_1_1");
    auto b = ReadFaceTake(kBeat2, "2_scott_0_2_2");
    ASSERT_TRUE(a.ok()) << a.status();
    ASSERT_TRUE(b.ok()) << b.status();
    train_ = new FaceTrainingTake(*std::move(a));
    test_ = new FaceTrainingTake(*std::move(b));
    auto m = TrainFaceModel(std::span(train_, 1), {});
    ASSERT_TRUE(m.ok()) << m.status();
    model_ = new std::shared_ptr<const FaceModel>(std::make_shared<const FaceModel>(*std::move(m)));
  }
  static std::vector<double> JawAtCapture(const std::vector<face::SpeechFaceFrame>& f, const FaceTrainingTake& t) {
    std::vector<double> out;
    for (std::size_t i = 0; i < t.jaw_open_deg.size(); ++i) {
      const std::size_t k = static_cast<std::size_t>(std::lround(i * t.jaw_frame_time_s / kFaceStepS));
      if (k >= f.size()) break;
      out.push_back(f[k].jaw_open_deg);
    }
    return out;
  }
  static FaceTrainingTake* train_;
  static FaceTrainingTake* test_;
  static std::shared_ptr<const FaceModel>* model_;
};
FaceTrainingTake* FaceModelBeat2::train_ = nullptr;
FaceTrainingTake* FaceModelBeat2::test_ = nullptr;
std::shared_ptr<const FaceModel>* FaceModelBeat2::model_ = nullptr;

TEST_F(FaceModelBeat2, JawFromSpeechItNeverHeardBeatsTheJawOfOtherSpeech) {
  const auto offline = AnalyzeFace(test_->samples, **model_);
  const auto live = AnalyzeFaceLive(test_->samples, *model_, 0.02);
  const double other = Pearson(train_->jaw_open_deg, test_->jaw_open_deg);
  const double r_offline = Pearson(JawAtCapture(offline, *test_), test_->jaw_open_deg);
  const double r_live = Pearson(JawAtCapture(live, *test_), test_->jaw_open_deg);
  EXPECT_GT(r_offline, other + 0.2) << "other speech " << other;
  EXPECT_GT(r_live, other + 0.2) << "other speech " << other;
}

TEST_F(FaceModelBeat2, ThesisCategoriesOfARealClipBeatChance) {
  const auto offline = AnalyzeFace(test_->samples, **model_);
  std::array<int, face::kNumCategories> counts{};
  int speech = 0, right = 0;
  std::size_t p = 0;
  for (const auto& f : offline) {
    while (p < test_->phones.size() && test_->phones[p].end_s <= f.time_s) ++p;
    face::PhoneClass c = face::PhoneClass::kSil;
    if (p < test_->phones.size() && test_->phones[p].start_s <= f.time_s) (void)face::PhoneToClass(test_->phones[p].phone, &c);
    if (c == face::PhoneClass::kSil) continue;
    const int cat = static_cast<int>(face::kClassCategory[static_cast<int>(c)]);
    std::array<float, face::kNumCategories> cats;
    face::ClassesToCategories(f.classes, &cats);
    ++speech;
    ++counts[cat];
    right += face::Dominant(cats) == cat;
  }
  const double chance = static_cast<double>(*std::max_element(counts.begin(), counts.end())) / speech;
  EXPECT_GT(static_cast<double>(right) / speech, chance + 0.1) << "chance " << chance;
}

TEST_F(FaceModelBeat2, LiveFramesNeedNoAudioPastTheChunk) {
  FaceStream s(*model_);
  std::vector<face::SpeechFaceFrame> out;
  const std::size_t chunk = 320;  // 20 ms
  for (std::size_t i = 0; i + chunk <= 16000; i += chunk) {
    s.Push(std::span<const float>(test_->samples).subspan(i, chunk), &out);
    // Every frame up to the audio received is out: t_k <= received.
    const double received_s = static_cast<double>(i + chunk) / kFaceSampleRateHz;
    ASSERT_FALSE(out.empty());
    EXPECT_NEAR(out.back().time_s, received_s, 1e-9);
  }
  for (std::size_t k = 0; k < out.size(); ++k) EXPECT_NEAR(out[k].time_s, k * kFaceStepS, 1e-9);
  // The same frames whatever the chunking.
  const auto other = AnalyzeFaceLive(std::span<const float>(test_->samples).first(16000), *model_, 0.05);
  ASSERT_GE(other.size(), out.size());
  for (std::size_t k = 0; k < out.size(); ++k) EXPECT_NEAR(other[k].jaw_open_deg, out[k].jaw_open_deg, 1e-4);
}

TEST_F(FaceModelBeat2, TheModelFileRoundTripsAndBadOnesAreRefused) {
  const std::string text = FaceModelToJson(**model_);
  auto back = FaceModelFromJson(text, "face_model.json");
  ASSERT_TRUE(back.ok()) << back.status();
  const auto a = AnalyzeFace(std::span<const float>(test_->samples).first(32000), **model_);
  const auto b = AnalyzeFace(std::span<const float>(test_->samples).first(32000), *back);
  for (std::size_t k = 0; k < a.size(); ++k) EXPECT_NEAR(a[k].jaw_open_deg, b[k].jaw_open_deg, 1e-3);
  EXPECT_EQ(back->min_closure_frames, (*model_)->min_closure_frames);
  EXPECT_EQ(back->live_min_closure_frames, (*model_)->live_min_closure_frames);
  // A file written before the live hold had its own value holds one for both.
  std::string one_hold = text;
  const std::string live_key = "\"live_min_closure_frames\":" + std::to_string((*model_)->live_min_closure_frames) + ",";
  const std::size_t live_at = one_hold.find(live_key);
  ASSERT_NE(live_at, std::string::npos);
  one_hold.erase(live_at, live_key.size());
  auto old = FaceModelFromJson(one_hold, "old.json");
  ASSERT_TRUE(old.ok()) << old.status();
  EXPECT_EQ(old->live_min_closure_frames, (*model_)->min_closure_frames);
  std::string long_hold = text;
  const std::string key = "\"min_closure_frames\":";
  const std::size_t at = long_hold.find(key);
  ASSERT_NE(at, std::string::npos);
  long_hold.insert(at + key.size(), "9");  // 10 -> 910 frames
  auto refused = FaceModelFromJson(long_hold, "m.json");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(std::string(refused.status().message()).find("min_closure_frames"), std::string::npos) << refused.status();
  auto bad = FaceModelFromJson(R"({"format": "kinemo-face-model", "version": 1, "mean": [1]})", "m.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(std::string(bad.status().message()).rfind("m.json: mean:", 0), 0u) << bad.status();
}

// The shortest run of frames where B/P/M dominates (runs touching the ends
// left out), and how many runs there are.
std::pair<int, int> ShortestClosure(const std::vector<face::SpeechFaceFrame>& f) {
  const int bpm = static_cast<int>(face::PhoneClass::kBPM);
  int shortest = 1 << 30, runs = 0;
  std::size_t k = 0;
  while (k < f.size()) {
    if (face::Dominant(f[k].classes) != bpm) {
      ++k;
      continue;
    }
    std::size_t end = k;
    while (end < f.size() && face::Dominant(f[end].classes) == bpm) ++end;
    if (k > 0 && end < f.size()) {
      shortest = std::min(shortest, static_cast<int>(end - k));
      ++runs;
    }
    k = end;
  }
  return {shortest, runs};
}

TEST_F(FaceModelBeat2, ShortLipClosuresAreHeldOfflineAndLive) {
  const FaceModel& model = **model_;
  ASSERT_GE(model.min_closure_frames, 4);
  ASSERT_GE(model.live_min_closure_frames, 4);
  std::vector<FacePhone> phones;
  for (const auto& p : test_->phones) phones.push_back({p.start_s, p.end_s, p.phone});
  FaceModel unheld = model;
  unheld.min_closure_frames = 0;
  unheld.live_min_closure_frames = 0;
  const std::span<const float> speech(test_->samples);
  // Without the hold, the speech of a real take shows closures shorter than
  // the minimum; with it, none (offline with phones and without, live).
  const auto before = ShortestClosure(AnalyzeFace(speech, unheld, phones));
  ASSERT_GT(before.second, 10);
  EXPECT_LT(before.first, model.min_closure_frames);
  for (const auto& frames : {AnalyzeFace(speech, model, phones), AnalyzeFace(speech, model)}) {
    const auto [shortest, runs] = ShortestClosure(frames);
    EXPECT_GT(runs, 10);
    EXPECT_GE(shortest, model.min_closure_frames);
  }
  const auto [shortest_live, runs_live] = ShortestClosure(AnalyzeFaceLive(speech, *model_, 0.02));
  EXPECT_GT(runs_live, 10);
  EXPECT_GE(shortest_live, model.live_min_closure_frames);
}

TEST_F(FaceModelBeat2, BlinksOnARealClipComeAtAPlausibleRate) {
  const auto speech = AnalyzeFace(test_->samples, **model_);
  const double duration = speech.back().time_s;
  const face::FaceTrack t = face::ComposeTrack(speech, {}, face::Expression::kNeutral, 0, 1.0 / 30, duration);
  int blinks = 0;
  for (std::size_t i = 1; i < t.frames.size(); ++i) {
    blinks += t.frames[i].blink_left > 0.5f && t.frames[i - 1].blink_left <= 0.5f;
  }
  const double per_min = blinks / (duration / 60);
  // People blink 15-30 times a minute in conversation (docs/face.md).
  EXPECT_GT(per_min, 10);
  EXPECT_LT(per_min, 40);
}

}  // namespace
}  // namespace kinemo::prosody
