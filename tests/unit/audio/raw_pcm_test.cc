// Headerless PCM: the real goforward.raw (16 kHz s16le mono) and encodings
// built from it.
#include <bit>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/audio/decode.h"
#include "common/audio/wav_writer.h"
#include "tests/unit/audio/audio_test_util.h"

namespace kinemo::audio {
namespace {

using ::testing::HasSubstr;
using testing::SpeechPath;

const RawPcmFormat kGoForward{PcmEncoding::kS16Le, 16000, 1};

DecodedAudio LoadGoForward() {
  auto audio = DecodeRawPcmFile(SpeechPath("goforward.raw"), kGoForward);
  EXPECT_TRUE(audio.ok()) << audio.status();
  return *std::move(audio);
}

void AppendLe(std::vector<std::uint8_t>& out, uint64_t bits, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<std::uint8_t>(bits >> (8 * i)));
}

TEST(RawPcmTest, DecodesTheRealRecording) {
  const DecodedAudio audio = LoadGoForward();
  EXPECT_EQ(audio.format, "raw");
  EXPECT_EQ(audio.subtype, "s16le");
  EXPECT_EQ(audio.sample_rate_hz, 16000);
  EXPECT_EQ(audio.channels, 1);
  EXPECT_EQ(audio.frames(), 89160 / 2);
  EXPECT_NEAR(audio.duration_s, 2.78625, 1e-12);
  EXPECT_GT(ToDbfs(audio.rms), -45.0);
  EXPECT_GT(audio.peak, 0.05f);
}

TEST(RawPcmTest, MatchesLibsndfileOnTheSameSamples) {
  // Our raw conversion and libsndfile's WAV reader scale identically.
  const DecodedAudio raw = LoadGoForward();
  auto wav = EncodeWav(raw.samples, 16000, 1, WavSampleFormat::kPcm16);
  ASSERT_TRUE(wav.ok());
  auto decoded = DecodeAudio(std::span<const std::uint8_t>(*wav));
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->samples, raw.samples);
  EXPECT_EQ(decoded->peak, raw.peak);
  EXPECT_NEAR(decoded->rms, raw.rms, 1e-12);
}

TEST(RawPcmTest, EveryEncodingAndStereo) {
  const DecodedAudio ref = LoadGoForward();
  const auto ints = [&](float x, double scale) {
    return static_cast<int64_t>(std::llround(static_cast<double>(x) * scale));
  };
  for (PcmEncoding enc : {PcmEncoding::kS16Le, PcmEncoding::kS24Le, PcmEncoding::kS32Le,
                          PcmEncoding::kF32Le, PcmEncoding::kF64Le, PcmEncoding::kU8}) {
    SCOPED_TRACE(std::string(PcmEncodingName(enc)));
    std::vector<std::uint8_t> bytes;
    for (float x : ref.samples) {
      for (int c = 0; c < 2; ++c) {  // stereo, the same speech on both channels
        switch (enc) {
          case PcmEncoding::kS16Le: AppendLe(bytes, static_cast<uint64_t>(ints(x, 32768.0)), 2); break;
          case PcmEncoding::kS24Le: AppendLe(bytes, static_cast<uint64_t>(ints(x, 8388608.0)), 3); break;
          case PcmEncoding::kS32Le: AppendLe(bytes, static_cast<uint64_t>(ints(x, 2147483648.0)), 4); break;
          case PcmEncoding::kF32Le: AppendLe(bytes, std::bit_cast<uint32_t>(x), 4); break;
          case PcmEncoding::kF64Le: AppendLe(bytes, std::bit_cast<uint64_t>(static_cast<double>(x)), 8); break;
          case PcmEncoding::kU8: AppendLe(bytes, static_cast<uint64_t>(128 + ints(x, 128.0)), 1); break;
        }
      }
    }
    ASSERT_EQ(bytes.size(), ref.samples.size() * 2 * BytesPerSample(enc));
    auto audio = DecodeRawPcm(std::span<const std::uint8_t>(bytes), {enc, 16000, 2});
    ASSERT_TRUE(audio.ok()) << audio.status();
    EXPECT_EQ(audio->channels, 2);
    EXPECT_EQ(audio->subtype, PcmEncodingName(enc));
    ASSERT_EQ(audio->samples.size(), ref.samples.size());
    if (enc == PcmEncoding::kU8) {
      EXPECT_GT(testing::SnrDb(ref.samples, audio->samples), 15.0);
    } else {
      EXPECT_EQ(audio->samples, ref.samples);  // 16-bit values are exact in all of these
    }
  }
}

TEST(RawPcmTest, PartialTrailingFrameIsAnError) {
  auto bytes = testing::ReadBytes(SpeechPath("goforward.raw"));
  bytes.push_back(0);
  auto odd = DecodeRawPcm(std::span<const std::uint8_t>(bytes), kGoForward);
  ASSERT_FALSE(odd.ok());
  EXPECT_EQ(odd.status().message(),
            "raw.bytes: 89161 bytes is not a whole number of 2-byte frames (s16le x 1 channel): 1 "
            "trailing byte of a partial frame");
  bytes.resize(89160 - 2);  // whole samples but half a stereo frame
  auto stereo = DecodeRawPcm(std::span<const std::uint8_t>(bytes), {PcmEncoding::kS16Le, 16000, 2});
  ASSERT_FALSE(stereo.ok());
  EXPECT_THAT(stereo.status().message(),
              HasSubstr("89158 bytes is not a whole number of 4-byte frames (s16le x 2 channels): "
                        "2 trailing bytes"));
}

TEST(RawPcmTest, AppendForLiveChunks) {
  // Chunks of any whole-frame size add up to the whole decode; a bad chunk
  // appends nothing.
  const auto bytes = testing::ReadBytes(SpeechPath("goforward.raw"));
  const DecodedAudio whole = LoadGoForward();
  std::vector<float> out;
  out.reserve(whole.samples.size());
  const float* before = out.data();
  std::size_t pos = 0;
  std::size_t chunk = 2;
  while (pos < bytes.size()) {
    const std::size_t n = std::min(chunk, bytes.size() - pos);
    ASSERT_TRUE(AppendPcmAsMono(std::span(bytes).subspan(pos, n), PcmEncoding::kS16Le, 1,
                                NonFinitePolicy::kReject, out)
                    .ok());
    pos += n;
    chunk = chunk * 3 % 2000 + 2;  // even sizes 2..2000
    chunk += chunk % 2;
  }
  EXPECT_EQ(out, whole.samples);
  EXPECT_EQ(out.data(), before);  // reserved capacity: no reallocation

  const std::size_t size = out.size();
  auto bad = AppendPcmAsMono(std::span(bytes).subspan(0, 3), PcmEncoding::kS16Le, 1,
                             NonFinitePolicy::kReject, out);
  EXPECT_FALSE(bad.ok());
  EXPECT_EQ(out.size(), size);
}

TEST(RawPcmTest, NonFiniteFloats) {
  const DecodedAudio ref = LoadGoForward();
  std::vector<std::uint8_t> bytes;
  for (std::size_t i = 0; i < ref.samples.size(); ++i) {
    float x = ref.samples[i];
    if (i == 320) x = std::numeric_limits<float>::infinity();
    if (i == 321) x = -std::numeric_limits<float>::infinity();
    if (i == 322) x = std::numeric_limits<float>::quiet_NaN();
    AppendLe(bytes, std::bit_cast<uint32_t>(x), 4);
  }
  const RawPcmFormat format{PcmEncoding::kF32Le, 16000, 1};
  auto rejected = DecodeRawPcm(std::span<const std::uint8_t>(bytes), format);
  ASSERT_FALSE(rejected.ok());
  EXPECT_THAT(rejected.status().message(),
              HasSubstr("audio.samples[320]: Inf at frame 320 (channel 0, t=0.0200 s)"));

  DecodeOptions options;
  options.non_finite = NonFinitePolicy::kZero;
  auto zeroed = DecodeRawPcm(std::span<const std::uint8_t>(bytes), format, options);
  ASSERT_TRUE(zeroed.ok()) << zeroed.status();
  EXPECT_EQ(zeroed->non_finite_samples, 3);
  EXPECT_EQ(zeroed->samples[321], 0.0f);

  std::vector<float> out;
  int64_t count = 0;
  ASSERT_TRUE(AppendPcmAsMono(std::span<const std::uint8_t>(bytes), PcmEncoding::kF32Le, 1,
                              NonFinitePolicy::kZero, out, &count)
                  .ok());
  EXPECT_EQ(count, 3);
  EXPECT_TRUE(AppendPcmAsMono(std::span<const std::uint8_t>(bytes), PcmEncoding::kF32Le, 1,
                              NonFinitePolicy::kReject, out)
                  .code() == absl::StatusCode::kInvalidArgument);
}

// Found by tests/fuzz/audio_fuzz (corpus: regression-raw-f32-7ch-mix-overflow.raw):
// loud channels summed in float overflowed to Inf, also under kZero.
TEST(RawPcmTest, LoudChannelsMixWithoutOverflow) {
  const float loud = 0.75f * std::numeric_limits<float>::max();
  for (int channels : {2, 7}) {
    std::vector<std::uint8_t> bytes;
    for (int f = 0; f < 100; ++f) {
      for (int c = 0; c < channels; ++c)
        AppendLe(bytes, std::bit_cast<uint32_t>(f % 2 ? loud : -loud), 4);
    }
    std::vector<float> out;
    int64_t zeroed = 0;
    ASSERT_TRUE(AppendPcmAsMono(std::span<const std::uint8_t>(bytes), PcmEncoding::kF32Le, channels,
                                NonFinitePolicy::kZero, out, &zeroed)
                    .ok());
    EXPECT_EQ(zeroed, 0);
    ASSERT_EQ(out.size(), 100u);
    for (int f = 0; f < 100; ++f)
      ASSERT_EQ(out[static_cast<std::size_t>(f)], f % 2 ? loud : -loud) << channels;
  }
  // A double beyond the float range is no sample: refused like Inf.
  std::vector<std::uint8_t> bytes;
  AppendLe(bytes, std::bit_cast<uint64_t>(1e300), 8);
  auto refused = DecodeRawPcm(std::span<const std::uint8_t>(bytes),
                              RawPcmFormat{PcmEncoding::kF64Le, 16000, 1});
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.status().message(), HasSubstr("audio.samples[0]: Inf"));
}

TEST(RawPcmTest, FormatErrors) {
  const auto bytes = testing::ReadBytes(SpeechPath("goforward.raw"));
  const std::span<const std::uint8_t> span(bytes);
  auto zero_rate = DecodeRawPcm(span, {PcmEncoding::kS16Le, 0, 1});
  ASSERT_FALSE(zero_rate.ok());
  EXPECT_THAT(zero_rate.status().message(),
              HasSubstr("audio.sample_rate_hz: 0 is not a valid rate"));
  auto no_channels = DecodeRawPcm(span, {PcmEncoding::kS16Le, 16000, 0});
  ASSERT_FALSE(no_channels.ok());
  EXPECT_THAT(no_channels.status().message(), HasSubstr("audio.channels: 0"));
  auto too_long = DecodeRawPcm(span, kGoForward, [] {
    DecodeOptions o;
    o.limits.max_duration_s = 2.0;
    return o;
  }());
  ASSERT_FALSE(too_long.ok());
  EXPECT_THAT(too_long.status().message(), HasSubstr("audio.duration_s: 2.786 s"));
  auto empty = DecodeRawPcm(std::string_view(), kGoForward);
  ASSERT_FALSE(empty.ok());
  EXPECT_THAT(empty.status().message(), HasSubstr("audio.bytes: empty input"));

  auto encoding = ParsePcmEncoding("s16be");
  ASSERT_FALSE(encoding.ok());
  EXPECT_EQ(encoding.status().message(),
            "raw.encoding: 's16be' is not supported (s16le, s24le, s32le, f32le, f64le, u8)");
  for (const char* name : {"s16le", "s24le", "s32le", "f32le", "f64le", "u8"}) {
    auto parsed = ParsePcmEncoding(name);
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(PcmEncodingName(*parsed), name);
  }
}

}  // namespace
}  // namespace kinemo::audio
