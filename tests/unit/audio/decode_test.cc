// Decoding real speech, and format variants built from it (24-bit, 32-bit,
// float, double, 8-bit, stereo 48 kHz, 8 kHz, multichannel, FLAC, OGG).
#include "common/audio/decode.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sndfile.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "common/audio/resample.h"
#include "common/audio/wav_writer.h"
#include "tests/unit/audio/audio_test_util.h"

namespace kinemo::audio {
namespace {

using ::testing::HasSubstr;
using testing::Correlation;
using testing::LibrivoxClips;
using testing::MaxAbsDiff;
using testing::SnrDb;
using testing::SpeechPath;
using testing::TempDir;

const std::string kClip = "sense_and_sensibility_01_austen_64kb-0870.wav";

DecodedAudio LoadClip() {
  auto audio = DecodeAudioFile(SpeechPath(kClip));
  EXPECT_TRUE(audio.ok()) << audio.status();
  return *std::move(audio);
}

TEST(DecodeTest, RealLibrivoxClips) {
  const double expected_s[] = {7.1, 2.99, 5.3, 6.05, 3.29};
  const auto clips = LibrivoxClips();
  for (std::size_t i = 0; i < clips.size(); ++i) {
    SCOPED_TRACE(clips[i]);
    auto audio = DecodeAudioFile(clips[i]);
    ASSERT_TRUE(audio.ok()) << audio.status();
    EXPECT_EQ(audio->sample_rate_hz, 16000);
    EXPECT_EQ(audio->channels, 1);
    EXPECT_EQ(audio->format, "wav");
    EXPECT_EQ(audio->subtype, "pcm_16");
    EXPECT_EQ(audio->format_description, "WAV (Microsoft)");
    EXPECT_EQ(audio->subtype_description, "Signed 16 bit PCM");
    EXPECT_NEAR(audio->duration_s, expected_s[i], 1e-9);
    EXPECT_EQ(audio->frames(), std::llround(expected_s[i] * 16000));
    // Real speech: audible, not clipped.
    EXPECT_GT(ToDbfs(audio->rms), -40.0);
    EXPECT_LT(ToDbfs(audio->rms), -10.0);
    EXPECT_GT(audio->peak, 0.05f);
    EXPECT_LE(audio->peak, 1.0f);
    for (float x : audio->samples) ASSERT_TRUE(x >= -1.0f && x < 1.0f);
  }
}

TEST(DecodeTest, BytesAndFileShareOnePath) {
  const auto bytes = testing::ReadBytes(SpeechPath(kClip));
  auto from_bytes = DecodeAudio(std::span<const std::uint8_t>(bytes));
  ASSERT_TRUE(from_bytes.ok()) << from_bytes.status();
  // A gRPC `bytes` field arrives as std::string.
  const std::string as_string(bytes.begin(), bytes.end());
  auto from_string = DecodeAudio(std::string_view(as_string));
  ASSERT_TRUE(from_string.ok()) << from_string.status();
  const DecodedAudio from_file = LoadClip();
  EXPECT_EQ(from_bytes->samples, from_file.samples);
  EXPECT_EQ(from_string->samples, from_file.samples);
}

TEST(DecodeTest, ScalingMatchesSixteenBitIntegers) {
  // 16-bit PCM decodes to k / 32768 exactly (libsndfile's normalisation).
  const DecodedAudio audio = LoadClip();
  for (float x : audio.samples) {
    const float k = x * 32768.0f;
    ASSERT_EQ(k, std::round(k));
  }
}

struct WavVariant {
  WavSampleFormat format;
  const char* subtype;
  double min_snr_db;  // vs the 16-bit original
};

class WavVariantTest : public ::testing::TestWithParam<WavVariant> {};

TEST_P(WavVariantTest, DecodesLikeTheOriginal) {
  const WavVariant v = GetParam();
  const DecodedAudio original = LoadClip();
  TempDir dir;
  const std::string path = dir.File(std::string("variant_") + v.subtype + ".wav");
  ASSERT_TRUE(WriteWavFile(path, original.samples, 16000, 1, v.format).ok());
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->format, "wav");
  EXPECT_EQ(audio->subtype, v.subtype);
  EXPECT_EQ(audio->sample_rate_hz, 16000);
  ASSERT_EQ(audio->samples.size(), original.samples.size());
  EXPECT_GE(SnrDb(original.samples, audio->samples), v.min_snr_db);
}

// 16-bit values are exact in 24/32-bit PCM and in float; 8-bit loses ~48 dB
// of range, leaving ~25 dB SNR on this quiet-ish speech (RMS -24 dBFS).
INSTANTIATE_TEST_SUITE_P(Formats, WavVariantTest,
                         ::testing::Values(WavVariant{WavSampleFormat::kPcm16, "pcm_16", 1e9},
                                           WavVariant{WavSampleFormat::kPcm24, "pcm_24", 1e9},
                                           WavVariant{WavSampleFormat::kPcm32, "pcm_32", 1e9},
                                           WavVariant{WavSampleFormat::kFloat32, "float", 1e9},
                                           WavVariant{WavSampleFormat::kFloat64, "double", 1e9},
                                           WavVariant{WavSampleFormat::kPcmU8, "pcm_u8", 20.0}),
                         [](const auto& info) { return std::string(info.param.subtype); });

TEST(DecodeTest, StereoAveragesChannels) {
  const DecodedAudio original = LoadClip();
  std::vector<float> silent(original.samples.size(), 0.0f);
  std::vector<float> inverted(original.samples.size());
  for (std::size_t i = 0; i < inverted.size(); ++i) inverted[i] = -original.samples[i];
  TempDir dir;

  // Speech on the left, silence on the right → half the speech (exact in float).
  const std::string left_only = dir.File("left_only.wav");
  ASSERT_TRUE(WriteWavFile(left_only, testing::Interleave({original.samples, silent}), 16000, 2,
                           WavSampleFormat::kFloat32)
                  .ok());
  auto audio = DecodeAudioFile(left_only);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->channels, 2);
  ASSERT_EQ(audio->samples.size(), original.samples.size());
  for (std::size_t i = 0; i < original.samples.size(); ++i) {
    ASSERT_EQ(audio->samples[i], 0.5f * original.samples[i]);
  }
  // Peak and RMS are over the source channels: peak of the left channel.
  EXPECT_EQ(audio->peak, original.peak);
  EXPECT_NEAR(audio->rms, original.rms / std::sqrt(2.0), 1e-6);

  // Opposite channels cancel.
  const std::string cancel = dir.File("cancel.wav");
  ASSERT_TRUE(WriteWavFile(cancel, testing::Interleave({original.samples, inverted}), 16000, 2,
                           WavSampleFormat::kPcm16)
                  .ok());
  audio = DecodeAudioFile(cancel);
  ASSERT_TRUE(audio.ok()) << audio.status();
  for (float x : audio->samples) ASSERT_EQ(x, 0.0f);
}

// Found by tests/fuzz/audio_fuzz (corpus: regression-mix-overflow.wav):
// the float sum of two channels near the float limit was +Inf, a non-finite
// "sample" in audio that passed the non-finite check.
TEST(DecodeTest, LoudChannelsMixWithoutOverflow) {
  const DecodedAudio original = LoadClip();
  const float loud = 0.9f * std::numeric_limits<float>::max();
  std::vector<float> left(original.samples.size()), right(original.samples.size());
  for (std::size_t i = 0; i < left.size(); ++i) {
    left[i] = original.samples[i] >= 0 ? loud : -loud;
    right[i] = left[i];
  }
  TempDir dir;
  for (int channels : {2, 3}) {
    std::vector<std::vector<float>> all(static_cast<std::size_t>(channels), left);
    all[1] = right;
    const std::string path = dir.File("loud.wav");
    ASSERT_TRUE(
        WriteWavFile(path, testing::Interleave(all), 16000, channels, WavSampleFormat::kFloat32)
            .ok());
    auto audio = DecodeAudioFile(path);
    ASSERT_TRUE(audio.ok()) << audio.status();
    ASSERT_EQ(audio->samples.size(), left.size());
    for (std::size_t i = 0; i < left.size(); ++i) ASSERT_EQ(audio->samples[i], left[i]) << channels;
  }
}

TEST(DecodeTest, Stereo48kHzResamplesBackToTheOriginal) {
  const DecodedAudio original = LoadClip();
  auto up = Resample(original.samples, 16000, 48000);
  ASSERT_TRUE(up.ok()) << up.status();
  std::vector<float> quiet(up->size());
  for (std::size_t i = 0; i < quiet.size(); ++i) quiet[i] = 0.5f * (*up)[i];
  TempDir dir;
  const std::string path = dir.File("stereo48k.wav");
  ASSERT_TRUE(
      WriteWavFile(path, testing::Interleave({*up, quiet}), 48000, 2, WavSampleFormat::kPcm24)
          .ok());
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->sample_rate_hz, 48000);
  EXPECT_EQ(audio->channels, 2);
  EXPECT_EQ(audio->subtype, "pcm_24");
  EXPECT_NEAR(audio->duration_s, original.duration_s, 1e-9);
  auto analysis = ToAnalysisRate(*std::move(audio), 16000);
  ASSERT_TRUE(analysis.ok()) << analysis.status();
  EXPECT_EQ(analysis->sample_rate_hz, 16000);
  ASSERT_EQ(analysis->samples.size(), original.samples.size());
  // mono = 0.75 · speech; the round trip keeps everything up to ~7.3 kHz,
  // which is all there is in these clips (measured: ~72 dB).
  std::vector<float> expected(original.samples.size());
  for (std::size_t i = 0; i < expected.size(); ++i) expected[i] = 0.75f * original.samples[i];
  EXPECT_GT(SnrDb(expected, analysis->samples), 55.0);
  EXPECT_GT(Correlation(expected, analysis->samples), 0.999);
}

TEST(DecodeTest, Telephone8kHz) {
  const DecodedAudio original = LoadClip();
  auto narrow = Resample(original.samples, 16000, 8000);
  ASSERT_TRUE(narrow.ok());
  TempDir dir;
  const std::string path = dir.File("phone8k.wav");
  ASSERT_TRUE(WriteWavFile(path, *narrow, 8000, 1, WavSampleFormat::kPcm16).ok());
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->sample_rate_hz, 8000);
  EXPECT_GT(SnrDb(*narrow, audio->samples), 60.0);  // only 16-bit rounding
  auto analysis = ToAnalysisRate(*std::move(audio), 16000);
  ASSERT_TRUE(analysis.ok());
  ASSERT_EQ(analysis->samples.size(), original.samples.size());
  // Speech energy is mostly below 4 kHz: the band-limited copy stays close.
  EXPECT_GT(Correlation(original.samples, analysis->samples), 0.95);
}

TEST(DecodeTest, MultichannelWavexIsAveraged) {
  const DecodedAudio original = LoadClip();
  const std::size_t n = original.samples.size();
  std::vector<std::vector<float>> channels(4, std::vector<float>(n));
  for (std::size_t i = 0; i < n; ++i) {
    channels[0][i] = original.samples[i];
    channels[1][i] = 0.5f * original.samples[i];
    channels[2][i] = 0.25f * original.samples[i];
    channels[3][i] = 0.25f * original.samples[i];
  }
  TempDir dir;
  const std::string path = dir.File("quad.wav");
  ASSERT_TRUE(
      WriteWavFile(path, testing::Interleave(channels), 16000, 4, WavSampleFormat::kFloat32).ok());
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->format, "wavex");
  EXPECT_EQ(audio->channels, 4);
  std::vector<float> expected(n);
  for (std::size_t i = 0; i < n; ++i) expected[i] = 0.5f * original.samples[i];
  EXPECT_LT(MaxAbsDiff(expected, audio->samples), 1e-7);
}

TEST(DecodeTest, FlacIsLossless) {
  const DecodedAudio original = LoadClip();
  TempDir dir;
  const std::string path = dir.File("clip.flac");
  ASSERT_TRUE(testing::WriteWithSndfile(path, original.samples, 16000, 1,
                                        SF_FORMAT_FLAC | SF_FORMAT_PCM_16))
      << "this libsndfile cannot write FLAC";
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->format, "flac");
  EXPECT_EQ(audio->subtype, "pcm_16");
  EXPECT_EQ(audio->samples, original.samples);
}

TEST(DecodeTest, OggVorbisDecodes) {
  const DecodedAudio original = LoadClip();
  TempDir dir;
  const std::string path = dir.File("clip.ogg");
  ASSERT_TRUE(testing::WriteWithSndfile(path, original.samples, 16000, 1,
                                        SF_FORMAT_OGG | SF_FORMAT_VORBIS))
      << "this libsndfile cannot write OGG/Vorbis";
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->format, "ogg");
  EXPECT_EQ(audio->subtype, "vorbis");
  EXPECT_EQ(audio->sample_rate_hz, 16000);
  EXPECT_NEAR(static_cast<double>(audio->frames()), static_cast<double>(original.frames()), 16.0);
  EXPECT_GT(Correlation(original.samples, audio->samples), 0.95);  // lossy codec
}

TEST(DecodeTest, OggOpusDecodes) {
  // Opus only runs at 8/12/16/24/48 kHz; 16 kHz speech is its home ground.
  const DecodedAudio original = LoadClip();
  TempDir dir;
  const std::string path = dir.File("clip.opus");
  ASSERT_TRUE(testing::WriteWithSndfile(path, original.samples, 16000, 1,
                                        SF_FORMAT_OGG | SF_FORMAT_OPUS))
      << "this libsndfile cannot write OGG/Opus";
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->format, "ogg");
  EXPECT_EQ(audio->subtype, "opus");
  EXPECT_GT(audio->duration_s, original.duration_s - 0.05);
  EXPECT_LT(audio->duration_s, original.duration_s + 0.05);
}

TEST(DecodeTest, Mp3Decodes) {
  const DecodedAudio original = LoadClip();
  TempDir dir;
  const std::string path = dir.File("clip.mp3");
  ASSERT_TRUE(testing::WriteWithSndfile(path, original.samples, 16000, 1,
                                        SF_FORMAT_MPEG | SF_FORMAT_MPEG_LAYER_III))
      << "this libsndfile cannot write MP3";
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->format, "mpeg");
  EXPECT_EQ(audio->subtype, "mp3");
  EXPECT_EQ(audio->sample_rate_hz, 16000);
  EXPECT_NEAR(audio->duration_s, original.duration_s, 0.05);
  EXPECT_GT(Correlation(original.samples, audio->samples), 0.9);  // lossy, gapless-aligned
}

TEST(DecodeTest, AiffDecodes) {
  const DecodedAudio original = LoadClip();
  TempDir dir;
  const std::string path = dir.File("clip.aiff");
  ASSERT_TRUE(testing::WriteWithSndfile(path, original.samples, 16000, 1,
                                        SF_FORMAT_AIFF | SF_FORMAT_PCM_16));
  auto audio = DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok()) << audio.status();
  EXPECT_EQ(audio->format, "aiff");
  EXPECT_EQ(audio->samples, original.samples);
}

TEST(DecodeTest, ContainersOutsideTheAcceptedListAreRefused) {
  const DecodedAudio original = LoadClip();
  TempDir dir;
  const std::string path = dir.File("clip.au");
  ASSERT_TRUE(testing::WriteWithSndfile(path, original.samples, 16000, 1,
                                        SF_FORMAT_AU | SF_FORMAT_PCM_16));
  auto refused = DecodeAudioFile(path);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.status().message(), HasSubstr("audio.format: 'au'"));
  EXPECT_THAT(refused.status().message(), HasSubstr("accepted_formats"));

  DecodeOptions options;
  options.accepted_formats.push_back("au");
  auto accepted = DecodeAudioFile(path, options);
  ASSERT_TRUE(accepted.ok()) << accepted.status();
  EXPECT_EQ(accepted->samples, original.samples);
}

TEST(DecodeTest, SupportedFormatsListsTheBuild) {
  const auto formats = SupportedFormats();
  EXPECT_THAT(formats, ::testing::Contains(HasSubstr("wav: WAV (Microsoft)")));
  EXPECT_THAT(formats, ::testing::Contains(HasSubstr("flac:")));
  EXPECT_THAT(formats, ::testing::Contains(HasSubstr("ogg:")));
}

}  // namespace
}  // namespace kinemo::audio
