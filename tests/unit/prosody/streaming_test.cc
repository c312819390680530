// The live analyzer on real speech: chunks of any size give the offline
// result (frames identical once the Viterbi lag has passed; syllables and
// accents close), with events emitted within the documented latency.
#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/match.h"

#include "services/prosody/core/analyzer.h"
#include "services/prosody/core/streaming.h"
#include "tests/unit/prosody/test_util.h"

namespace kinemo::prosody {
namespace {

using testing::LoadClip;
using testing::ReferenceClips;

struct LiveRun {
  ProsodyResult result;
  std::vector<StreamEvent> events;
  double reach_s = 0, frame_latency_s = 0, accent_latency_s = 0;
};

LiveRun RunLive(const std::vector<float>& samples, int rate, std::size_t chunk) {
  LiveRun run;
  auto analyzer = StreamingAnalyzer::Create(rate, {}, /*emit_frames=*/true);
  EXPECT_TRUE(analyzer.ok()) << analyzer.status();
  for (std::size_t i = 0; i < samples.size(); i += chunk) {
    const std::size_t n = std::min(chunk, samples.size() - i);
    EXPECT_TRUE((*analyzer)->Push(std::span(samples).subspan(i, n), &run.events).ok());
  }
  (*analyzer)->Finish(&run.events);
  run.result = (*analyzer)->result();
  run.reach_s = (*analyzer)->reach_s();
  run.frame_latency_s = (*analyzer)->frame_latency_s();
  run.accent_latency_s = (*analyzer)->accent_latency_s();
  return run;
}

TEST(StreamingTest, MatchesOfflineForAnyChunkSize) {
  for (const auto& stem : ReferenceClips()) {
    const auto audio = LoadClip(stem);
    auto offline = AnalyzeSamples(audio.samples, audio.sample_rate_hz, {});
    ASSERT_TRUE(offline.ok());
    for (std::size_t chunk : {std::size_t{1}, std::size_t{37}, std::size_t{160},
                              std::size_t{4000}, audio.samples.size()}) {
      if (chunk == 1 && stem != ReferenceClips().front()) continue;  // slow-ish; once suffices
      const LiveRun live = RunLive(audio.samples, audio.sample_rate_hz, chunk);
      const auto& lf = live.result.frames;
      const auto& of = offline->frames;
      ASSERT_EQ(lf.size(), of.size()) << stem << " chunk " << chunk;
      // Frames arrive exactly once and in order.
      std::size_t streamed = 0;
      for (const StreamEvent& e : live.events) {
        if (e.kind != StreamEvent::Kind::kFrames) continue;
        for (const Frame& f : e.frames) {
          ASSERT_LT(streamed, of.size());
          EXPECT_DOUBLE_EQ(f.time_s, of[streamed].time_s);
          ++streamed;
        }
      }
      EXPECT_EQ(streamed, of.size());
      int same_f0 = 0, intensity_equal = 0;
      for (std::size_t i = 0; i < of.size(); ++i) {
        same_f0 += lf[i].voiced == of[i].voiced &&
                   std::fabs(lf[i].f0_hz - of[i].f0_hz) <= 1e-3 * std::max(1.0, of[i].f0_hz);
        intensity_equal += std::fabs(lf[i].intensity_db - of[i].intensity_db) < 1e-6;
      }
      EXPECT_EQ(intensity_equal, static_cast<int>(of.size())) << stem;
      // The running peak (live) differs from the global peak (offline) only
      // in quiet frames before the loudest part.
      EXPECT_GE(same_f0, 0.97 * of.size()) << stem << " chunk " << chunk;
      // Syllables: same boundaries for nearly all.
      int matched = 0;
      for (const Syllable& s : offline->syllables) {
        for (const Syllable& l : live.result.syllables) {
          if (std::fabs(l.start_s - s.start_s) < 0.015 && std::fabs(l.end_s - s.end_s) < 0.015) {
            ++matched;
            break;
          }
        }
      }
      // The running silence reference (live) differs from the recording's
      // maximum (offline) before the loudest syllable: allow one difference.
      EXPECT_GE(matched, std::min(0.9 * offline->syllables.size(),
                                  offline->syllables.size() - 1.0))
          << stem;
      // Accents: at least half the offline accents are found live at the same
      // PAPT (live normalises by the maxima so far, offline by the whole clip's).
      int accents = 0;
      for (const Accent& a : offline->accents) {
        for (const Accent& l : live.result.accents) {
          if (std::fabs(l.time_s - a.time_s) < 0.03) {
            ++accents;
            break;
          }
        }
      }
      EXPECT_GE(accents, 0.5 * offline->accents.size()) << stem;
    }
  }
}

TEST(StreamingTest, EventsComeWithinTheirAlgorithmicLatency) {
  const auto audio = LoadClip(ReferenceClips().at(0));
  const LiveRun live = RunLive(audio.samples, audio.sample_rate_hz, 160);  // 10 ms chunks
  const double chunk_s = 0.01;
  int syllables = 0, accents = 0;
  for (const StreamEvent& e : live.events) {
    if (e.emitted_at_s >= live.result.duration_s - 1e-9) continue;  // flushed by Finish
    switch (e.kind) {
      case StreamEvent::Kind::kFrames:
        // A frame is final viterbi_lag + reach after its centre.
        EXPECT_LE(e.emitted_at_s - e.frames.back().time_s,
                  live.frame_latency_s + chunk_s + 0.011);
        break;
      case StreamEvent::Kind::kSyllable: {
        ++syllables;
        // Certain when intensity has risen min_dip_db after the trough, or
        // silence starts; bounded by half a second on read speech.
        EXPECT_GE(e.emitted_at_s, e.syllable.end_s);
        EXPECT_LE(e.emitted_at_s - e.syllable.end_s, 0.5);
        break;
      }
      case StreamEvent::Kind::kAccent:
        ++accents;
        EXPECT_GE(e.accent.strength, 0);
        EXPECT_LE(e.accent.strength, 1);
        EXPECT_LE(e.emitted_at_s - e.accent.syllable_end_s, live.accent_latency_s + 0.6);
        break;
      default:
        break;
    }
  }
  EXPECT_GT(syllables, 5);
  EXPECT_GT(accents, 0);
}

TEST(StreamingTest, RejectsNonFiniteSamplesAndPushAfterFinish) {
  auto analyzer = StreamingAnalyzer::Create(16000, {}, false);
  ASSERT_TRUE(analyzer.ok());
  std::vector<StreamEvent> events;
  std::vector<float> bad(100, 0.0f);
  bad[42] = INFINITY;
  auto s = (*analyzer)->Push(bad, &events);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StartsWith(s.message(), "samples[42]")) << s;
  (*analyzer)->Finish(&events);
  EXPECT_EQ((*analyzer)->Push(std::vector<float>(10, 0.0f), &events).code(),
            absl::StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace kinemo::prosody
