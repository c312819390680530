// Resampling real speech with libsoxr: lengths, round trips, and a stream
// fed in chunks agreeing with the whole-buffer result.
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "tests/unit/audio/audio_test_util.h"

namespace kinemo::audio {
namespace {

using ::testing::HasSubstr;
using testing::SnrDb;

std::vector<float> Speech() {
  auto audio = DecodeAudioFile(testing::SpeechPath("sense_and_sensibility_01_austen_64kb-0890.wav"));
  EXPECT_TRUE(audio.ok()) << audio.status();
  return audio->samples;
}

// Feeds `in` in chunks whose sizes cycle through `sizes`, then flushes.
std::vector<float> Stream(const std::vector<float>& in, int in_hz, int out_hz,
                          const std::vector<std::size_t>& sizes) {
  auto resampler = StreamingResampler::Create(in_hz, out_hz);
  EXPECT_TRUE(resampler.ok()) << resampler.status();
  std::vector<float> out;
  std::size_t pos = 0;
  std::size_t k = 0;
  while (pos < in.size()) {
    const std::size_t n = std::min(sizes[k++ % sizes.size()], in.size() - pos);
    EXPECT_TRUE(resampler->Process(std::span(in).subspan(pos, n), out).ok());
    pos += n;
  }
  EXPECT_TRUE(resampler->Flush(out).ok());
  EXPECT_EQ(resampler->input_frames(), static_cast<int64_t>(in.size()));
  EXPECT_EQ(resampler->output_frames(), static_cast<int64_t>(out.size()));
  return out;
}

TEST(ResampleTest, OutputLength) {
  const auto speech = Speech();  // 84800 samples at 16 kHz
  for (int out_hz : {8000, 11025, 16000, 22050, 44100, 48000}) {
    SCOPED_TRACE(out_hz);
    auto out = Resample(speech, 16000, out_hz);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_EQ(static_cast<int64_t>(out->size()),
              std::llround(static_cast<double>(speech.size()) * out_hz / 16000));
  }
}

TEST(ResampleTest, EqualRatesCopy) {
  const auto speech = Speech();
  auto out = Resample(speech, 16000, 16000);
  ASSERT_TRUE(out.ok());
  EXPECT_EQ(*out, speech);
  EXPECT_EQ(Stream(speech, 16000, 16000, {333}), speech);
}

TEST(ResampleTest, RoundTripsKeepTheSpeech) {
  const auto speech = Speech();
  for (int mid_hz : {22050, 44100, 48000}) {
    SCOPED_TRACE(mid_hz);
    auto up = Resample(speech, 16000, mid_hz);
    ASSERT_TRUE(up.ok());
    auto back = Resample(*up, mid_hz, 16000);
    ASSERT_TRUE(back.ok());
    ASSERT_EQ(back->size(), speech.size());
    // Aligned (no delay) and within the passband: high SNR (measured ~72 dB:
    // these clips carry nothing above ~7 kHz).
    EXPECT_GT(SnrDb(speech, *back), 60.0);
  }
}

TEST(ResampleTest, DownsampledSpeechMatchesAnIndependentPath) {
  // 48 kHz → 16 kHz must agree with the 16 kHz original that 48 kHz was made
  // from, whatever the quality setting.
  const auto speech = Speech();
  auto up = Resample(speech, 16000, 48000, {ResampleQuality::kVeryHigh});
  ASSERT_TRUE(up.ok());
  for (ResampleQuality q :
       {ResampleQuality::kMedium, ResampleQuality::kHigh, ResampleQuality::kVeryHigh}) {
    auto down = Resample(*up, 48000, 16000, {q});
    ASSERT_TRUE(down.ok());
    EXPECT_GT(testing::Correlation(speech, *down), 0.999);
  }
}

TEST(StreamingResamplerTest, ChunkedOutputMatchesWholeBuffer) {
  const auto speech = Speech();
  for (auto [in_hz, out_hz] : {std::pair{16000, 48000}, std::pair{16000, 8000},
                               std::pair{16000, 22050}, std::pair{16000, 44100}}) {
    SCOPED_TRACE(std::to_string(in_hz) + "->" + std::to_string(out_hz));
    auto whole = Resample(speech, in_hz, out_hz);
    ASSERT_TRUE(whole.ok());
    for (const std::vector<std::size_t>& sizes :
         std::vector<std::vector<std::size_t>>{{1}, {7}, {160}, {1024}, {100000},
                                               {0, 13, 1, 997, 4096, 2, 320}}) {
      const auto streamed = Stream(speech, in_hz, out_hz, sizes);
      ASSERT_EQ(streamed.size(), whole->size()) << "first chunk size " << sizes[0];
      EXPECT_LT(testing::MaxAbsDiff(*whole, streamed), 1e-5) << "first chunk size " << sizes[0];
    }
  }
}

TEST(StreamingResamplerTest, OutputArrivesWhileStreaming) {
  const auto speech = Speech();
  auto resampler = StreamingResampler::Create(16000, 48000);
  ASSERT_TRUE(resampler.ok());
  std::vector<float> out;
  // 1 s of input: most of 1 s of output is available before the flush; the
  // rest is the filter's latency.
  ASSERT_TRUE(resampler->Process(std::span(speech).first(16000), out).ok());
  EXPECT_GT(out.size(), 48000u * 9 / 10);
  EXPECT_LE(out.size(), 48000u);
  EXPECT_GE(resampler->pending_output_frames(), 0);
  const std::size_t before_flush = out.size();
  ASSERT_TRUE(resampler->Flush(out).ok());
  EXPECT_EQ(out.size(), 48000u);
  EXPECT_GT(out.size(), before_flush);
}

TEST(StreamingResamplerTest, FlushEndsTheStreamUntilReset) {
  const auto speech = Speech();
  auto resampler = StreamingResampler::Create(16000, 8000);
  ASSERT_TRUE(resampler.ok());
  std::vector<float> first;
  ASSERT_TRUE(resampler->Process(speech, first).ok());
  ASSERT_TRUE(resampler->Flush(first).ok());
  ASSERT_TRUE(resampler->Flush(first).ok());  // idempotent
  std::vector<float> ignored;
  auto after = resampler->Process(speech, ignored);
  EXPECT_EQ(after.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(after.message(), HasSubstr("Reset()"));

  ASSERT_TRUE(resampler->Reset().ok());
  std::vector<float> second;
  ASSERT_TRUE(resampler->Process(speech, second).ok());
  ASSERT_TRUE(resampler->Flush(second).ok());
  EXPECT_EQ(first, second);
}

TEST(StreamingResamplerTest, MoveKeepsTheStream) {
  const auto speech = Speech();
  auto created = StreamingResampler::Create(16000, 48000);
  ASSERT_TRUE(created.ok());
  StreamingResampler a = *std::move(created);
  std::vector<float> out;
  ASSERT_TRUE(a.Process(std::span(speech).first(5000), out).ok());
  StreamingResampler b = std::move(a);
  ASSERT_TRUE(b.Process(std::span(speech).subspan(5000), out).ok());
  ASSERT_TRUE(b.Flush(out).ok());
  auto whole = Resample(speech, 16000, 48000);
  ASSERT_TRUE(whole.ok());
  ASSERT_EQ(out.size(), whole->size());
  EXPECT_LT(testing::MaxAbsDiff(*whole, out), 1e-5);
}

TEST(ResampleTest, InvalidRates) {
  const std::vector<float> x(100, 0.0f);
  auto zero = Resample(x, 0, 16000);
  ASSERT_FALSE(zero.ok());
  EXPECT_EQ(zero.status().message(), "resample.in_rate_hz: 0 is not a valid rate (1..10000000 Hz)");
  auto negative = StreamingResampler::Create(16000, -5);
  ASSERT_FALSE(negative.ok());
  EXPECT_THAT(negative.status().message(), HasSubstr("resample.out_rate_hz: -5"));
  DecodedAudio audio;
  audio.samples = x;
  audio.sample_rate_hz = 16000;
  EXPECT_FALSE(ToAnalysisRate(audio, 0).ok());
}

TEST(ResampleTest, EmptyInput) {
  auto out = Resample({}, 16000, 48000);
  ASSERT_TRUE(out.ok());
  EXPECT_TRUE(out->empty());
}

}  // namespace
}  // namespace kinemo::audio
