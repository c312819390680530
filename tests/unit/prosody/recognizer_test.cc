// The Sphinx recognizer on real LibriVox speech (tests/data/speech with its
// transcription): recognised words overlap the transcript, keywords are
// spotted where they are spoken, phones tile the clip.
#include <algorithm>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "services/prosody/core/recognizer.h"
#include "tests/unit/prosody/test_util.h"

namespace kinemo::prosody {
namespace {

constexpr char kClip[] = "sense_and_sensibility_01_austen_64kb-0870";
// From tests/data/speech/transcription.
constexpr char kTranscript[] =
    "and mister john dashwood had then leisure to consider how much there might be prudently in "
    "his power to do for them";

TEST(RecognizerTest, WordsKeywordsAndPhonesOnRealSpeech) {
  auto recognizer = SphinxRecognizer::Create({});
  ASSERT_TRUE(recognizer.ok()) << recognizer.status();
  const auto audio = testing::LoadClip(kClip);
  ASSERT_EQ(audio.sample_rate_hz, 16000);

  auto words = (*recognizer)->Words(audio.samples);
  ASSERT_TRUE(words.ok()) << words.status();
  std::set<std::string> truth;
  std::istringstream ss(kTranscript);
  for (std::string w; ss >> w;) truth.insert(w);
  int hits = 0;
  for (const auto& w : *words) {
    hits += truth.count(w.word) > 0;
    EXPECT_LT(w.start_s, w.end_s);
  }
  EXPECT_GE(hits, 14) << "of " << words->size() << " recognised words";

  auto spotted = (*recognizer)->Keywords(audio.samples, {"consider", "power"}, 0);
  ASSERT_TRUE(spotted.ok()) << spotted.status();
  // "consider" is spoken at about 2.9-3.4 s, "power" at about 5.7-6.0 s.
  bool consider = false, power = false;
  for (const auto& w : *spotted) {
    EXPECT_TRUE(w.keyword);
    consider |= w.word == "consider" && w.start_s > 2.7 && w.end_s < 3.6;
    power |= w.word == "power" && w.start_s > 5.5 && w.end_s < 6.2;
  }
  EXPECT_TRUE(consider);
  EXPECT_TRUE(power);

  auto unknown = (*recognizer)->Keywords(audio.samples, {"power", "qzxv"}, 0);
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StartsWith(unknown.status().message(), "keywords[1]"));

  auto phones = (*recognizer)->Phones(audio.samples);
  ASSERT_TRUE(phones.ok()) << phones.status();
  ASSERT_GT(phones->size(), 40u);
  EXPECT_EQ(phones->front().phone, "SIL");
  for (std::size_t i = 1; i < phones->size(); ++i) {
    EXPECT_NEAR((*phones)[i].start_s, (*phones)[i - 1].end_s, 0.011);
  }
}

// Live spotting: the same keywords found at the same places whatever the
// chunk size, each reported once, soon after it is spoken.
TEST(RecognizerTest, KeywordStreamSpotsLiveInChunksOfAnySize) {
  auto recognizer = SphinxRecognizer::Create({});
  ASSERT_TRUE(recognizer.ok()) << recognizer.status();
  const auto audio = testing::LoadClip(kClip);
  for (const std::size_t chunk : {160u, 1000u, 4096u}) {
    auto stream = (*recognizer)->OpenKeywordStream({"consider", "power"}, 0);
    ASSERT_TRUE(stream.ok()) << stream.status();
    std::vector<RecognizedWord> found;
    std::vector<double> reported_at_s;
    for (std::size_t i = 0; i < audio.samples.size(); i += chunk) {
      const std::size_t n = std::min(chunk, audio.samples.size() - i);
      const std::size_t before = found.size();
      ASSERT_TRUE((*stream)->Process({audio.samples.data() + i, n}, &found).ok());
      for (std::size_t k = before; k < found.size(); ++k) reported_at_s.push_back((*stream)->processed_s());
    }
    ASSERT_TRUE((*stream)->Finish(&found).ok());
    while (reported_at_s.size() < found.size()) reported_at_s.push_back((*stream)->processed_s());
    int consider = 0, power = 0;
    for (std::size_t k = 0; k < found.size(); ++k) {
      const auto& w = found[k];
      EXPECT_TRUE(w.keyword);
      if (w.word == "consider" && w.start_s > 2.7 && w.end_s < 3.6) ++consider;
      if (w.word == "power" && w.start_s > 5.5 && w.end_s < 6.2) ++power;
      // Reported within a second of the word's end (live, not at the end of the clip).
      EXPECT_LT(reported_at_s[k] - w.end_s, 1.0) << w.word << " with chunks of " << chunk;
    }
    EXPECT_EQ(consider, 1) << "chunks of " << chunk;
    EXPECT_EQ(power, 1) << "chunks of " << chunk;
  }
  EXPECT_EQ((*recognizer)->OpenKeywordStream({"qzxv"}, 0).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ((*recognizer)->OpenKeywordStream({}, 0).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(RecognizerTest, MissingModelIsAFailedPreconditionNamingTheField) {
  RecognizerConfig c;
  c.model_dir = "/nonexistent/en-us";
  auto r = SphinxRecognizer::Create(c);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "recognizer.model_dir")) << r.status();
}

}  // namespace
}  // namespace kinemo::prosody
