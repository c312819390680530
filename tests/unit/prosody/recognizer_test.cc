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

TEST(RecognizerTest, MissingModelIsAFailedPreconditionNamingTheField) {
  RecognizerConfig c;
  c.model_dir = "/nonexistent/en-us";
  auto r = SphinxRecognizer::Create(c);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "recognizer.model_dir")) << r.status();
}

}  // namespace
}  // namespace kinemo::prosody
