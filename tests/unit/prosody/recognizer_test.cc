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

std::vector<std::string> TranscriptWords() {
  std::vector<std::string> words;
  std::istringstream ss(kTranscript);
  for (std::string w; ss >> w;) words.push_back(w);
  return words;
}

std::string Sequence(const std::vector<RecognizedPhone>& phones) {
  std::string out;
  for (const auto& p : phones) {
    if (p.phone != "SIL") out += " " + p.phone;
  }
  return out + " ";
}

// Share of `truth`'s phones (silence excluded) whose midpoint falls in a phone
// of `hyp` with the same label.
double Matched(const std::vector<RecognizedPhone>& truth, const std::vector<RecognizedPhone>& hyp) {
  int n = 0, same = 0;
  for (const auto& p : truth) {
    if (p.phone == "SIL") continue;
    ++n;
    const double mid = 0.5 * (p.start_s + p.end_s);
    for (const auto& h : hyp) {
      if (h.start_s <= mid && mid < h.end_s) {
        same += h.phone == p.phone;
        break;
      }
    }
  }
  return n > 0 ? static_cast<double>(same) / n : 0.0;
}

// Phones from 0 to the end of the audio (within `end_tolerance_s`: Sphinx
// makes no frame of the last 25 ms window of each utterance), each starting
// where the previous one ended.
void ExpectTiling(const std::vector<RecognizedPhone>& phones, double duration_s, const std::string& what,
                  double end_tolerance_s = 0.05) {
  ASSERT_FALSE(phones.empty()) << what;
  EXPECT_NEAR(phones.front().start_s, 0.0, 0.011) << what;
  EXPECT_NEAR(phones.back().end_s, duration_s, end_tolerance_s) << what;
  for (std::size_t i = 0; i < phones.size(); ++i) {
    EXPECT_LT(phones[i].start_s, phones[i].end_s) << what << " phone " << i;
    if (i > 0) {
      EXPECT_NEAR(phones[i].start_s, phones[i - 1].end_s, 0.011) << what << " phone " << i;
    }
  }
}

// Forced alignment: the transcript's phones in order (one pronunciation per
// word), timed over the whole clip.
TEST(RecognizerTest, AlignmentFollowsTheTranscript) {
  auto recognizer = SphinxRecognizer::Create({});
  ASSERT_TRUE(recognizer.ok()) << recognizer.status();
  const auto audio = testing::LoadClip(kClip);
  auto phones = (*recognizer)->AlignPhones(audio.samples, TranscriptWords());
  ASSERT_TRUE(phones.ok()) << phones.status();
  ExpectTiling(*phones, audio.samples.size() / 16000.0, "alignment");
  const std::string seq = Sequence(*phones);
  // "mister john dashwood" and "consider" as CMUdict spells them.
  EXPECT_NE(seq.find(" M IH S T ER JH AA N D AE SH W UH D "), std::string::npos) << seq;
  EXPECT_NE(seq.find(" K AH N S IH D ER "), std::string::npos) << seq;
  auto unknown = (*recognizer)->AlignPhones(audio.samples, {"power", "qzxv"});
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StartsWith(unknown.status().message(), "words[1]")) << unknown.status();
  EXPECT_EQ((*recognizer)->AlignPhones(audio.samples, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// The default timed phones (the words found, aligned) against the forced
// alignment of the transcript (bench/tools/phone_eval.cc measures all
// clips: 0.88 matched, against 0.67 for the phone loop used before).
TEST(RecognizerTest, PhonesAgreeWithTheAlignedTranscript) {
  auto recognizer = SphinxRecognizer::Create({});
  ASSERT_TRUE(recognizer.ok()) << recognizer.status();
  const auto audio = testing::LoadClip(kClip);
  auto truth = (*recognizer)->AlignPhones(audio.samples, TranscriptWords());
  ASSERT_TRUE(truth.ok()) << truth.status();
  auto both = (*recognizer)->Recognize(audio.samples);
  ASSERT_TRUE(both.ok()) << both.status();
  ExpectTiling(both->phones, audio.samples.size() / 16000.0, "phones");
  EXPECT_GE(Matched(*truth, both->phones), 0.75) << Sequence(both->phones);
  EXPECT_GE(both->words.size(), 15u);
  // The phone grammar (live streams' method) on the whole clip.
  RecognizerConfig grammar;
  grammar.phone_search.method = PhoneMethod::kPhoneGrammar;
  auto g = SphinxRecognizer::Create(grammar);
  ASSERT_TRUE(g.ok()) << g.status();
  auto gp = (*g)->Phones(audio.samples);
  ASSERT_TRUE(gp.ok()) << gp.status();
  ExpectTiling(*gp, audio.samples.size() / 16000.0, "grammar phones");
  EXPECT_GE(Matched(*truth, *gp), 0.45) << Sequence(*gp);
}

// Live phones: reported while the audio flows (lag plus a chunk after their
// end), tiling the stream, the same for the same audio (each stream starts
// from the model's cepstral mean), and close to the aligned transcript.
TEST(RecognizerTest, PhoneStreamReportsPhonesLive) {
  auto recognizer = SphinxRecognizer::Create({});
  ASSERT_TRUE(recognizer.ok()) << recognizer.status();
  const auto audio = testing::LoadClip(kClip);
  const double duration = audio.samples.size() / 16000.0;
  auto truth = (*recognizer)->AlignPhones(audio.samples, TranscriptWords());
  ASSERT_TRUE(truth.ok()) << truth.status();
  std::vector<RecognizedPhone> first;
  for (const std::size_t chunk : {320u, 320u, 1600u}) {
    auto stream = (*recognizer)->OpenPhoneStream(0.3);
    ASSERT_TRUE(stream.ok()) << stream.status();
    std::vector<RecognizedPhone> phones;
    std::vector<double> reported_at_s;
    for (std::size_t i = 0; i < audio.samples.size(); i += chunk) {
      const std::size_t n = std::min(chunk, audio.samples.size() - i);
      ASSERT_TRUE((*stream)->Process({audio.samples.data() + i, n}, &phones).ok());
      while (reported_at_s.size() < phones.size()) reported_at_s.push_back((*stream)->processed_s());
    }
    const std::size_t live = phones.size();
    ASSERT_TRUE((*stream)->Finish(&phones).ok());
    const std::string what = kinemo::StrCat("chunks of ", chunk);
    ExpectTiling(phones, duration, what);
    EXPECT_GT(live, phones.size() * 3 / 4) << what << ": most phones before the end";
    const double bound = (*stream)->latency_s() + chunk / 16000.0 + 0.011;
    for (std::size_t k = 0; k < live; ++k) {
      EXPECT_LE(reported_at_s[k] - phones[k].end_s, bound) << what << " phone " << k;
    }
    EXPECT_GE(Matched(*truth, phones), 0.4) << what << Sequence(phones);
    if (first.empty()) {
      first = phones;
    } else if (chunk == 320u) {
      ASSERT_EQ(phones.size(), first.size());
      for (std::size_t k = 0; k < phones.size(); ++k) {
        EXPECT_EQ(phones[k].phone, first[k].phone);
        EXPECT_EQ(phones[k].start_s, first[k].start_s);
      }
    }
  }
  EXPECT_EQ((*recognizer)->OpenPhoneStream(0).status().code(), absl::StatusCode::kInvalidArgument);
}

// A stream longer than an utterance (30 s) is cut in a silence and goes on:
// the five clips end to end, twice (50 s).
TEST(RecognizerTest, LongPhoneStreamsGoOnAcrossUtterances) {
  auto recognizer = SphinxRecognizer::Create({});
  ASSERT_TRUE(recognizer.ok()) << recognizer.status();
  std::vector<float> speech;
  for (int round = 0; round < 2; ++round) {
    for (const std::string& stem : testing::ReferenceClips()) {
      const auto a = testing::LoadClip(stem);
      speech.insert(speech.end(), a.samples.begin(), a.samples.end());
    }
  }
  const double duration = speech.size() / 16000.0;
  ASSERT_GT(duration, 45);
  auto stream = (*recognizer)->OpenPhoneStream(0.3);
  ASSERT_TRUE(stream.ok()) << stream.status();
  std::vector<RecognizedPhone> phones;
  for (std::size_t i = 0; i < speech.size(); i += 1600) {
    ASSERT_TRUE((*stream)->Process({speech.data() + i, std::min<std::size_t>(1600, speech.size() - i)}, &phones).ok());
  }
  ASSERT_TRUE((*stream)->Finish(&phones).ok());
  ExpectTiling(phones, duration, "50 s stream", 0.1);
  int speech_after_30s = 0;
  for (const auto& p : phones) speech_after_30s += p.start_s > 31 && p.phone != "SIL";
  EXPECT_GT(speech_after_30s, 100);
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
