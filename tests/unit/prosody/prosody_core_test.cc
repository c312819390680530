// The prosody core on real speech (LibriVox clips in tests/data/speech),
// compared with Praat references made once (tests/data/prosody/README.md).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "absl/strings/match.h"

#include "common/audio/resample.h"
#include "services/prosody/core/analyzer.h"
#include "services/prosody/core/fft.h"
#include "services/prosody/core/pipeline.h"
#include "tests/unit/prosody/test_util.h"

namespace kinemo::prosody {
namespace {

using testing::DataPath;
using testing::LoadClip;
using testing::ReadCsv;
using testing::ReferenceClips;

TEST(RealFftTest, AutocorrelationMatchesDirectSum) {
  const auto clips = ReferenceClips();
  ASSERT_FALSE(clips.empty());
  const auto audio = LoadClip(clips[0]);
  ASSERT_GT(audio.samples.size(), 20000u);
  RealFft fft(1024);
  std::vector<float> in(1024, 0.0f), r(1024);
  std::vector<std::complex<float>> spectrum(513), work(512);
  for (int i = 0; i < 600; ++i) in[i] = audio.samples[16000 + i];
  fft.Autocorrelation(in, r, spectrum, work);
  for (int lag : {0, 1, 7, 80, 200, 423}) {
    double direct = 0;
    for (int i = 0; i + lag < 600; ++i) direct += static_cast<double>(in[i]) * in[i + lag];
    EXPECT_NEAR(r[lag], direct, 1e-4 * std::max(1.0, std::fabs(direct))) << "lag " << lag;
  }
}

TEST(PraatAgreementTest, PitchAndIntensityOnPraatGrids) {
  const auto clips = ReferenceClips();
  ASSERT_GE(clips.size(), 1u) << "no clip with a Praat reference in tests/data";
  int both = 0, within = 0, agree = 0, pitch_frames = 0, int_frames = 0, int_within = 0;
  for (const auto& stem : clips) {
    const auto audio = LoadClip(stem);
    ASSERT_FALSE(audio.samples.empty()) << stem;
    const auto pitch = ReadCsv(DataPath("prosody/" + stem + ".praat_pitch.csv"));
    const auto inten = ReadCsv(DataPath("prosody/" + stem + ".praat_intensity.csv"));
    ASSERT_GT(pitch.size(), 100u);
    ASSERT_GT(inten.size(), 100u);
    AnalysisOptions options;
    auto frames = AnalyzeFrames(audio.samples, audio.sample_rate_hz, options,
                                {pitch[0].time_s, static_cast<int>(pitch.size())});
    ASSERT_TRUE(frames.ok()) << frames.status();
    for (std::size_t i = 0; i < pitch.size(); ++i) {
      EXPECT_NEAR((*frames)[i].time_s, pitch[i].time_s, 1e-6);
      const bool pv = pitch[i].value > 0, kv = (*frames)[i].voiced;
      agree += pv == kv;
      ++pitch_frames;
      if (pv && kv) {
        ++both;
        within += std::fabs(1200 * std::log2((*frames)[i].f0_hz / pitch[i].value)) <= 50;
      }
    }
    auto iframes = AnalyzeFrames(audio.samples, audio.sample_rate_hz, options,
                                 {inten[0].time_s, static_cast<int>(inten.size())});
    ASSERT_TRUE(iframes.ok()) << iframes.status();
    for (std::size_t i = 0; i < inten.size(); ++i) {
      ++int_frames;
      int_within += std::fabs((*iframes)[i].intensity_db - inten[i].value) <= 1.0;
    }
  }
  const double f0_share = static_cast<double>(within) / both;
  const double voicing_share = static_cast<double>(agree) / pitch_frames;
  const double intensity_share = static_cast<double>(int_within) / int_frames;
  std::printf("Praat agreement over %zu clips: F0 within 50 cents %.4f (%d frames voiced in both), "
              "voicing %.4f, intensity within 1 dB %.4f\n",
              clips.size(), f0_share, both, voicing_share, intensity_share);
  EXPECT_GE(f0_share, 0.95);
  EXPECT_GE(voicing_share, 0.90);
  EXPECT_GE(intensity_share, 0.95);
}

TEST(AnalyzeTest, SyllablesAccentsAndPausesAreConsistent) {
  for (const auto& stem : ReferenceClips()) {
    const auto audio = LoadClip(stem);
    auto result = AnalyzeSamples(audio.samples, audio.sample_rate_hz, {});
    ASSERT_TRUE(result.ok()) << result.status();
    const ProsodyResult& r = *result;
    // 10 ms hop from 0 covering the whole clip.
    ASSERT_EQ(r.frames.size(),
              static_cast<std::size_t>(std::ceil(r.duration_s / 0.01 - 1e-9)));
    EXPECT_NEAR(r.frames[1].time_s - r.frames[0].time_s, 0.01, 1e-12);
    // Read speech: between 2 and 8 syllables per second.
    const double rate = r.syllables.size() / r.duration_s;
    EXPECT_GT(rate, 2.0) << stem;
    EXPECT_LT(rate, 8.0) << stem;
    double prev_end = -1;
    for (const Syllable& s : r.syllables) {
      EXPECT_GE(s.start_s, prev_end - 1e-9);
      EXPECT_GT(s.end_s, s.start_s);
      EXPECT_NEAR(s.length_s, s.end_s - s.start_s, 1e-9);
      EXPECT_GE(s.nucleus_time_s, s.start_s);
      EXPECT_LT(s.nucleus_time_s, s.end_s);
      if (s.voiced) {
        EXPECT_GE(s.f0_mean_hz, 75);
        EXPECT_LE(s.f0_mean_hz, 600);
      }
      prev_end = s.end_s;
    }
    ASSERT_FALSE(r.accents.empty()) << stem;
    double max_strength = 0;
    for (std::size_t i = 0; i < r.accents.size(); ++i) {
      const Accent& a = r.accents[i];
      const Syllable& s = r.syllables[a.syllable_index];
      EXPECT_EQ(s.accent_index, static_cast<int>(i));
      EXPECT_GE(a.time_s, s.start_s);
      EXPECT_LE(a.time_s, s.end_s);
      EXPECT_GT(a.strength, 0);
      EXPECT_LE(a.strength, 1);
      EXPECT_GE(a.strength, 0.3 - 1e-9);  // the default threshold
      EXPECT_GT(a.psi, 0);
      max_strength = std::max(max_strength, a.strength);
      if (i > 0) {
        EXPECT_GE(a.time_s - r.accents[i - 1].time_s, 0.3 - 1e-9);
      }
    }
    EXPECT_DOUBLE_EQ(max_strength, 1.0);
    for (const Pause& p : r.pauses) {
      EXPECT_GE(p.end_s - p.start_s, 0.2 - 1e-9);
      for (const Syllable& s : r.syllables) {
        EXPECT_FALSE(s.start_s < p.end_s - 1e-9 && s.end_s > p.start_s + 1e-9)
            << "syllable overlaps a pause in " << stem;
      }
    }
  }
}

TEST(AnalyzeTest, LowerAccentThresholdGivesMoreAccents) {
  const auto audio = LoadClip(ReferenceClips().at(0));
  AnalysisOptions strict, lax;
  strict.accent.threshold = 0.8;
  lax.accent.threshold = 0.1;
  lax.accent.min_distance_s = 0.1;
  auto a = AnalyzeSamples(audio.samples, audio.sample_rate_hz, strict);
  auto b = AnalyzeSamples(audio.samples, audio.sample_rate_hz, lax);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_LT(a->accents.size(), b->accents.size());
}

TEST(AnalyzeTest, BadOptionsNameTheField) {
  std::vector<float> samples(16000, 0.0f);
  AnalysisOptions o;
  o.pitch.floor_hz = 700;
  auto r = AnalyzeSamples(samples, 16000, o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "pitch.ceiling_hz")) << r.status();
  o = {};
  o.accent.threshold = 2;
  r = AnalyzeSamples(samples, 16000, o);
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "accent.threshold")) << r.status();
  r = AnalyzeSamples(samples, 1000, {});
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "sample_rate_hz")) << r.status();
  samples[123] = std::nanf("");
  r = AnalyzeSamples(samples, 16000, {});
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "samples[123]")) << r.status();
  // The first bad sample is named, whichever thread finds one.
  std::vector<float> longer(400000, 0.1f);
  longer[300001] = INFINITY;
  longer[200002] = -INFINITY;
  o = {};
  o.threads = 4;
  r = AnalyzeSamples(longer, 16000, o);
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "samples[200002]")) << r.status();
  o.threads = -1;
  r = AnalyzeSamples(samples, 16000, o);
  EXPECT_TRUE(absl::StartsWith(r.status().message(), "threads")) << r.status();
}

// One file's analysis over several threads: frame blocks in parallel, the
// Viterbi path in order. Every number is the same as on one thread, bit for
// bit (each frame's computation does not depend on the thread that runs it),
// on 25 s of real speech (the five LibriVox clips end to end: ten blocks).
TEST(ThreadsTest, AnyThreadCountGivesTheSameResultBitForBit) {
  std::vector<float> speech;
  for (const std::string& stem : ReferenceClips()) {
    const audio::DecodedAudio a = LoadClip(stem);
    ASSERT_EQ(a.sample_rate_hz, 16000);
    speech.insert(speech.end(), a.samples.begin(), a.samples.end());
  }
  ASSERT_GT(speech.size(), 20u * 16000);
  AnalysisOptions one;
  one.threads = 1;
  auto base = AnalyzeSamples(speech, 16000, one);
  ASSERT_TRUE(base.ok()) << base.status();
  ASSERT_GT(base->frames.size(), 2000u);
  ASSERT_GT(base->accents.size(), 10u);
  for (int threads : {2, 3, 8, 0}) {
    AnalysisOptions o;
    o.threads = threads;
    auto r = AnalyzeSamples(speech, 16000, o);
    ASSERT_TRUE(r.ok()) << r.status();
    ASSERT_EQ(r->frames.size(), base->frames.size());
    for (std::size_t k = 0; k < r->frames.size(); ++k) {
      const Frame& a = base->frames[k];
      const Frame& b = r->frames[k];
      ASSERT_TRUE(a.time_s == b.time_s && a.f0_hz == b.f0_hz && a.voiced == b.voiced &&
                  a.voicing_probability == b.voicing_probability && a.intensity_db == b.intensity_db)
          << "threads " << threads << ", frame " << k;
    }
    ASSERT_EQ(r->syllables.size(), base->syllables.size());
    ASSERT_EQ(r->accents.size(), base->accents.size());
    for (std::size_t i = 0; i < r->accents.size(); ++i) {
      EXPECT_EQ(r->accents[i].time_s, base->accents[i].time_s);
      EXPECT_EQ(r->accents[i].strength, base->accents[i].strength);
      EXPECT_EQ(r->accents[i].psi, base->accents[i].psi);
    }
    ASSERT_EQ(r->pauses.size(), base->pauses.size());
  }
}

// A stopped token ends the analysis before its next stage, with the
// token's reason (the prosody service passes the caller's deadline).
TEST(PipelineTest, StopsWhenItsCancelTokenStops) {
  const audio::DecodedAudio a = LoadClip(ReferenceClips().front());
  PipelineRequest request;
  CancelToken expired(CancelToken::Clock::now() - std::chrono::milliseconds(1));
  request.cancel = &expired;
  auto late = RunPipeline(a.samples, a.sample_rate_hz, request, nullptr);
  EXPECT_EQ(late.status().code(), absl::StatusCode::kDeadlineExceeded) << late.status();
  CancelToken cancelled;
  cancelled.Cancel();
  request.cancel = &cancelled;
  auto gone = RunPipeline(a.samples, a.sample_rate_hz, request, nullptr);
  EXPECT_EQ(gone.status().code(), absl::StatusCode::kCancelled) << gone.status();
  EXPECT_TRUE(absl::StartsWith(gone.status().message(), "analysis:")) << gone.status();
  CancelToken open(CancelToken::Clock::now() + std::chrono::hours(1));
  request.cancel = &open;
  EXPECT_TRUE(RunPipeline(a.samples, a.sample_rate_hz, request, nullptr).ok());
}

// The JSON frames are written directly (not through nlohmann::json, which
// was a third of the time on long files): the same document once parsed.
TEST(JsonTest, FramesReadBackAsNlohmannWritesThem) {
  const audio::DecodedAudio a = LoadClip(ReferenceClips().front());
  PipelineRequest request;
  auto result = RunPipeline(a.samples, a.sample_rate_hz, request, nullptr);
  ASSERT_TRUE(result.ok()) << result.status();
  // Values that exercise every notation: integers, small, large, negative.
  result->prosody.frames[0].f0_hz = 1e-7;
  result->prosody.frames[0].intensity_db = -300;
  result->prosody.frames[1].f0_hz = 123456789012345678.0;
  result->prosody.frames[1].intensity_db = 0.0001;
  result->prosody.frames[2].f0_hz = 1e21;
  result->prosody.frames[2].voicing_probability = -0.0;
  const std::string text = ToJson(*result, 3);
  const nlohmann::json parsed = nlohmann::json::parse(text);
  nlohmann::json expected = nlohmann::json::array();
  for (const Frame& f : result->prosody.frames) {
    expected.push_back({{"time_s", f.time_s},
                        {"f0_hz", f.f0_hz},
                        {"voiced", f.voiced},
                        {"voicing_probability", f.voicing_probability},
                        {"intensity_db", f.intensity_db}});
  }
  ASSERT_EQ(parsed["frames"].size(), expected.size());
  EXPECT_EQ(parsed["frames"], expected);
  // The layout is nlohmann's (its digits can differ in the last place where
  // its shortest-digit search, Grisu2, finds a tie or a longer string).
  for (const char* written : {"{\"f0_hz\":1e-07,\"intensity_db\":-300.0,",
                              "{\"f0_hz\":1.2345678901234568e+17,\"intensity_db\":0.0001,",
                              "{\"f0_hz\":1e+21,", "\"voicing_probability\":-0.0}"}) {
    EXPECT_NE(text.find(written), std::string::npos) << written;
  }
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(parsed["frames"][k]["f0_hz"].dump(), expected[k]["f0_hz"].dump());
    EXPECT_EQ(parsed["frames"][k]["intensity_db"].dump(), expected[k]["intensity_db"].dump());
  }
  EXPECT_TRUE(parsed.contains("syllables") && parsed.contains("accents") && parsed.contains("pauses"));
  EXPECT_FALSE(parsed.contains("recognizer_rtf"));
}

// Garbage in: sane output, never a crash.
TEST(GarbageTest, SilenceHasNoSpeech) {
  for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{100}, std::size_t{48000}}) {
    std::vector<float> silence(n, 0.0f);
    auto r = AnalyzeSamples(silence, 16000, {});
    ASSERT_TRUE(r.ok()) << r.status();
    for (const Frame& f : r->frames) EXPECT_FALSE(f.voiced);
    EXPECT_TRUE(r->syllables.empty());
    EXPECT_TRUE(r->accents.empty());
  }
}

TEST(GarbageTest, WhiteNoiseIsMostlyUnvoiced) {
  std::vector<float> noise(32000);
  uint32_t state = 12345;
  for (float& x : noise) {
    state = state * 1664525u + 1013904223u;
    x = (static_cast<float>(state >> 8) / 16777216.0f - 0.5f) * 0.5f;
  }
  auto r = AnalyzeSamples(noise, 16000, {});
  ASSERT_TRUE(r.ok()) << r.status();
  int voiced = 0;
  for (const Frame& f : r->frames) voiced += f.voiced;
  EXPECT_LT(voiced, static_cast<int>(r->frames.size()) / 10);
}

TEST(GarbageTest, ClippedSpeechKeepsItsPitch) {
  const auto audio = LoadClip(ReferenceClips().at(0));
  std::vector<float> clipped = audio.samples;
  for (float& x : clipped) x = std::clamp(x * 20.0f, -1.0f, 1.0f);
  auto a = AnalyzeSamples(audio.samples, audio.sample_rate_hz, {});
  auto b = AnalyzeSamples(clipped, audio.sample_rate_hz, {});
  ASSERT_TRUE(a.ok() && b.ok());
  int both = 0, within = 0;
  for (std::size_t i = 0; i < a->frames.size(); ++i) {
    if (a->frames[i].voiced && b->frames[i].voiced) {
      ++both;
      within += std::fabs(1200 * std::log2(a->frames[i].f0_hz / b->frames[i].f0_hz)) <= 50;
    }
  }
  EXPECT_GT(both, 100);
  EXPECT_GT(static_cast<double>(within) / both, 0.9);
}

TEST(GarbageTest, TelephoneRateAndHighRateGiveTheSamePitch) {
  const auto audio = LoadClip(ReferenceClips().at(0));
  auto base = AnalyzeSamples(audio.samples, audio.sample_rate_hz, {});
  ASSERT_TRUE(base.ok());
  for (int rate : {8000, 48000}) {
    auto resampled = audio::Resample(audio.samples, audio.sample_rate_hz, rate);
    ASSERT_TRUE(resampled.ok()) << resampled.status();
    auto r = AnalyzeSamples(*resampled, rate, {});
    ASSERT_TRUE(r.ok()) << r.status();
    int both = 0, within = 0;
    const std::size_t n = std::min(base->frames.size(), r->frames.size());
    for (std::size_t i = 0; i < n; ++i) {
      if (base->frames[i].voiced && r->frames[i].voiced) {
        ++both;
        within += std::fabs(1200 * std::log2(base->frames[i].f0_hz / r->frames[i].f0_hz)) <= 50;
      }
    }
    EXPECT_GT(static_cast<double>(within) / std::max(both, 1), 0.9) << rate;
    EXPECT_GT(r->syllables.size(), base->syllables.size() / 2) << rate;
  }
}

}  // namespace
}  // namespace kinemo::prosody
