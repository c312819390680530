// Writing WAV from real speech: exact round trips, clipping, bad input.
#include <limits>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/audio/decode.h"
#include "common/audio/wav_writer.h"
#include "tests/unit/audio/audio_test_util.h"

namespace kinemo::audio {
namespace {

using ::testing::HasSubstr;

std::vector<float> WriterSpeech() {
  auto audio = DecodeAudioFile(testing::SpeechPath("sense_and_sensibility_01_austen_64kb-0930.wav"));
  EXPECT_TRUE(audio.ok()) << audio.status();
  return audio->samples;
}

TEST(WavWriterTest, SixteenBitRoundTripIsBitExact) {
  const auto speech = WriterSpeech();
  auto bytes = EncodeWav(speech, 16000, 1, WavSampleFormat::kPcm16);
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  EXPECT_EQ(bytes->size(), 44 + 2 * speech.size());  // canonical header
  // Identical to the original file's bytes: same header, same samples.
  EXPECT_EQ(*bytes,
            testing::ReadBytes(testing::SpeechPath("sense_and_sensibility_01_austen_64kb-0930.wav")));
}

TEST(WavWriterTest, FloatKeepsValuesAndIntegersClip) {
  std::vector<float> loud = WriterSpeech();
  for (float& x : loud) x *= 4.0f;  // well past full scale
  auto as_float = EncodeWav(loud, 16000, 1, WavSampleFormat::kFloat32);
  ASSERT_TRUE(as_float.ok());
  auto decoded = DecodeAudio(std::span<const std::uint8_t>(*as_float));
  ASSERT_TRUE(decoded.ok());
  EXPECT_EQ(decoded->samples, loud);
  EXPECT_GT(decoded->peak, 1.0f);

  auto as_int = EncodeWav(loud, 16000, 1, WavSampleFormat::kPcm16);
  ASSERT_TRUE(as_int.ok());
  decoded = DecodeAudio(std::span<const std::uint8_t>(*as_int));
  ASSERT_TRUE(decoded.ok());
  for (float x : decoded->samples) ASSERT_TRUE(x >= -1.0f && x <= 1.0f);
  EXPECT_GE(decoded->peak, 0.999f);  // clipped, not wrapped around
}

TEST(WavWriterTest, FileWrite) {
  const auto speech = WriterSpeech();
  testing::TempDir dir;
  const std::string path = dir.File("out.wav");
  ASSERT_TRUE(WriteWavFile(path, speech, 16000, 1, WavSampleFormat::kPcm24).ok());
  auto decoded = DecodeAudioFile(path);
  ASSERT_TRUE(decoded.ok());
  EXPECT_EQ(decoded->subtype, "pcm_24");
  EXPECT_EQ(decoded->samples, speech);
  auto bad_dir = WriteWavFile("/nonexistent/dir/out.wav", speech, 16000, 1, WavSampleFormat::kPcm16);
  EXPECT_THAT(bad_dir.message(), HasSubstr("/nonexistent/dir/out.wav: cannot open for writing"));
}

TEST(WavWriterTest, BadInput) {
  const std::vector<float> three = {0.1f, 0.2f, 0.3f};
  EXPECT_THAT(EncodeWav(three, 16000, 2, WavSampleFormat::kPcm16).status().message(),
              HasSubstr("wav.samples: 3 samples is not a multiple of 2 channels"));
  EXPECT_THAT(EncodeWav(three, 0, 1, WavSampleFormat::kPcm16).status().message(),
              HasSubstr("wav.sample_rate_hz: 0"));
  EXPECT_THAT(EncodeWav(three, 16000, 0, WavSampleFormat::kPcm16).status().message(),
              HasSubstr("wav.channels: 0"));
  const std::vector<float> nan = {0.0f, std::numeric_limits<float>::quiet_NaN()};
  EXPECT_THAT(EncodeWav(nan, 16000, 1, WavSampleFormat::kFloat32).status().message(),
              HasSubstr("wav.samples[1]: NaN/Inf cannot be written"));
}

}  // namespace
}  // namespace kinemo::audio
