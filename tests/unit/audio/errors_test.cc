// Corrupt, truncated and out-of-limit input: always a clear Status, never a
// crash. Every corruption starts from a real WAV file.
#include <cmath>
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
using ::testing::StartsWith;
using testing::SpeechPath;

// 16 kHz mono 16-bit, canonical 44-byte header, 95680 data bytes.
const std::string kErrorClip = "sense_and_sensibility_01_austen_64kb-0880.wav";

std::vector<std::uint8_t> ClipBytes() { return testing::ReadBytes(SpeechPath(kErrorClip)); }

void Put32(std::vector<std::uint8_t>& b, std::size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void Put16(std::vector<std::uint8_t>& b, std::size_t at, uint16_t v) {
  b[at] = static_cast<std::uint8_t>(v);
  b[at + 1] = static_cast<std::uint8_t>(v >> 8);
}

StatusOr<DecodedAudio> Decode(const std::vector<std::uint8_t>& bytes,
                              const DecodeOptions& options = {}) {
  return DecodeAudio(std::span<const std::uint8_t>(bytes), options);
}

void ExpectInvalid(const StatusOr<DecodedAudio>& result, const std::string& substring) {
  ASSERT_FALSE(result.ok()) << "decoded " << result->frames() << " frames";
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument) << result.status();
  EXPECT_THAT(result.status().message(), HasSubstr(substring));
}

TEST(DecodeErrorsTest, ClipHasTheExpectedLayout) {
  const auto bytes = ClipBytes();
  ASSERT_EQ(bytes.size(), 95724u);
  ASSERT_EQ(std::memcmp(bytes.data() + 36, "data", 4), 0);
}

TEST(DecodeErrorsTest, EmptyInput) {
  ExpectInvalid(Decode({}), "audio.bytes: empty input (0 bytes)");
  ExpectInvalid(DecodeAudio(std::string_view()), "audio.bytes: empty input");
}

TEST(DecodeErrorsTest, GarbageBytes) {
  std::vector<std::uint8_t> noise(4096);
  uint32_t state = 12345;
  for (auto& b : noise) {
    state = state * 1664525u + 1013904223u;
    b = static_cast<std::uint8_t>(state >> 24);
  }
  ExpectInvalid(Decode(noise), "audio: cannot decode 4096 bytes starting with");
  const std::string text = "this is not audio, just a sentence about audio";
  ExpectInvalid(DecodeAudio(std::string_view(text)), "starting with 'this'");
}

TEST(DecodeErrorsTest, TruncatedHeaders) {
  const auto full = ClipBytes();
  for (std::size_t n : {1u, 3u, 4u, 8u, 11u, 12u, 16u, 20u, 24u, 35u, 36u, 40u, 43u}) {
    SCOPED_TRACE(n);
    const std::vector<std::uint8_t> cut(full.begin(), full.begin() + n);
    auto result = Decode(cut);
    ASSERT_FALSE(result.ok());
    EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_FALSE(result.status().message().empty());
  }
  // The data chunk's own header cut short.
  const std::vector<std::uint8_t> cut43(full.begin(), full.begin() + 43);
  ExpectInvalid(Decode(cut43), "wav: truncated chunk header at offset 36 (7 of 8 bytes)");
  // A complete header with none of its 95680 data bytes.
  const std::vector<std::uint8_t> header_only(full.begin(), full.begin() + 44);
  ExpectInvalid(Decode(header_only),
                "wav: truncated data chunk: header declares 95680 bytes at offset 44, only 0 "
                "present");
}

TEST(DecodeErrorsTest, TruncatedDataChunkIsDetected) {
  const auto full = ClipBytes();
  const std::vector<std::uint8_t> cut(full.begin(), full.begin() + 10000);
  ExpectInvalid(Decode(cut),
                "wav: truncated data chunk: header declares 95680 bytes at offset 44, only 9956 "
                "present (85724 missing)");

  // Opting in reads what is there.
  DecodeOptions options;
  options.allow_truncated = true;
  auto partial = Decode(cut, options);
  ASSERT_TRUE(partial.ok()) << partial.status();
  EXPECT_EQ(partial->frames(), 9956 / 2);
  auto whole = Decode(full);
  ASSERT_TRUE(whole.ok());
  EXPECT_TRUE(std::equal(partial->samples.begin(), partial->samples.end(), whole->samples.begin()));
}

TEST(DecodeErrorsTest, TruncatedMidFrame) {
  // An odd byte count cuts a 16-bit sample in half.
  const auto full = ClipBytes();
  const std::vector<std::uint8_t> cut(full.begin(), full.begin() + 10001);
  ExpectInvalid(Decode(cut), "wav: truncated data chunk");
}

TEST(DecodeErrorsTest, AbsurdDataChunkSize) {
  auto bytes = ClipBytes();
  Put32(bytes, 40, 0x7FFFFFF0u);
  ExpectInvalid(Decode(bytes), "wav: truncated data chunk: header declares 2147483632 bytes");
}

TEST(DecodeErrorsTest, AbsurdRiffSizeIsIgnoredWhenTheDataChunkIsWhole) {
  // The RIFF size only bounds the chunk list; libsndfile reads on, and the
  // data chunk (checked above) is what matters. Documented choice: accept.
  auto bytes = ClipBytes();
  Put32(bytes, 4, 0xFFFFFFF0u);
  auto result = Decode(bytes);
  ASSERT_TRUE(result.ok()) << result.status();
  auto original = Decode(ClipBytes());
  ASSERT_TRUE(original.ok());
  EXPECT_EQ(result->samples, original->samples);
}

TEST(DecodeErrorsTest, AbsurdFmtChunkSize) {
  auto bytes = ClipBytes();
  Put32(bytes, 16, 0xFFFFFF00u);
  auto result = Decode(bytes);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(result.status().message()), StartsWith("audio"));
}

TEST(DecodeErrorsTest, AbsurdHeaderFields) {
  struct Case {
    const char* name;
    std::size_t offset;
    int width;
    uint32_t value;
  };
  const Case cases[] = {
      {"channels=0", 22, 2, 0},          {"channels=65535", 22, 2, 65535},
      {"rate=0", 24, 4, 0},              {"rate=4e9", 24, 4, 4000000000u},
      {"rate=1", 24, 4, 1},              {"block_align=0", 32, 2, 0},
      {"bits=0", 34, 2, 0},              {"bits=7", 34, 2, 7},
      {"bits=65535", 34, 2, 65535},      {"format_tag=0x1234", 20, 2, 0x1234},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    auto bytes = ClipBytes();
    if (c.width == 2) {
      Put16(bytes, c.offset, static_cast<uint16_t>(c.value));
    } else {
      Put32(bytes, c.offset, c.value);
    }
    auto result = Decode(bytes);
    // Either refused with a message, or (for fields libsndfile recomputes,
    // like block_align) decoded to the same audio. Never a crash.
    if (result.ok()) {
      EXPECT_EQ(result->sample_rate_hz, 16000);
      EXPECT_EQ(result->channels, 1);
    } else {
      EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
      EXPECT_FALSE(result.status().message().empty());
    }
  }
  // The limits name the field when libsndfile itself accepts the header.
  auto bytes = ClipBytes();
  Put32(bytes, 24, 1);
  Put32(bytes, 28, 2);
  ExpectInvalid(Decode(bytes), "audio.sample_rate_hz: 1 is not a supported rate (8000..192000");
}

TEST(DecodeErrorsTest, ZeroLengthDataChunk) {
  auto bytes = ClipBytes();
  bytes.resize(44);
  Put32(bytes, 4, 36);
  Put32(bytes, 40, 0);
  ExpectInvalid(Decode(bytes), "audio.frames: no samples (0 frames of wav/pcm_16)");
  DecodeOptions options;
  options.allow_empty = true;
  auto empty = Decode(bytes, options);
  ASSERT_TRUE(empty.ok()) << empty.status();
  EXPECT_EQ(empty->frames(), 0);
  EXPECT_EQ(empty->duration_s, 0.0);
  EXPECT_EQ(empty->rms, 0.0);
}

TEST(DecodeErrorsTest, StreamedWavWithUnknownDataSizeReadsToTheEnd) {
  // Writers that stream (pipes) leave 0xFFFFFFFF in the size fields.
  auto bytes = ClipBytes();
  Put32(bytes, 4, 0xFFFFFFFFu);
  Put32(bytes, 40, 0xFFFFFFFFu);
  auto result = Decode(bytes);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->frames(), 95680 / 2);
}

// A float WAV of real speech with NaN and +Inf patched in.
std::vector<std::uint8_t> FloatWavWithNonFinite(int channels) {
  auto audio = DecodeAudioFile(SpeechPath(kErrorClip));
  EXPECT_TRUE(audio.ok());
  std::vector<float> interleaved;
  for (float x : audio->samples) {
    for (int c = 0; c < channels; ++c) interleaved.push_back(x);
  }
  auto wav = EncodeWav(interleaved, 16000, channels, WavSampleFormat::kFloat32);
  EXPECT_TRUE(wav.ok());
  std::vector<std::uint8_t> bytes = *wav;
  // Canonical float header: data starts at byte 44 + the 'fact' chunk (12)
  // for float files written by libsndfile; find "data".
  std::size_t data = 12;
  while (std::memcmp(bytes.data() + data, "data", 4) != 0) {
    uint32_t size = 0;
    std::memcpy(&size, bytes.data() + data + 4, 4);
    data += 8 + size + (size & 1);
  }
  data += 8;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  std::memcpy(bytes.data() + data + 4 * 1001, &nan, 4);
  std::memcpy(bytes.data() + data + 4 * 2001, &inf, 4);
  return bytes;
}

TEST(DecodeErrorsTest, NonFiniteFloatsAreRejectedByDefault) {
  ExpectInvalid(Decode(FloatWavWithNonFinite(1)),
                "audio.samples[1001]: NaN at frame 1001 (channel 0, t=0.0626 s)");
  ExpectInvalid(Decode(FloatWavWithNonFinite(2)),
                "audio.samples[1001]: NaN at frame 500 (channel 1");
}

TEST(DecodeErrorsTest, NonFiniteFloatsCanBeZeroed) {
  DecodeOptions options;
  options.non_finite = NonFinitePolicy::kZero;
  auto result = Decode(FloatWavWithNonFinite(1), options);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->non_finite_samples, 2);
  EXPECT_EQ(result->samples[1001], 0.0f);
  EXPECT_EQ(result->samples[2001], 0.0f);
  EXPECT_TRUE(std::isfinite(result->rms));
  EXPECT_LE(result->peak, 1.0f);
}

TEST(DecodeErrorsTest, LimitsAreCheckedBeforeDecoding) {
  const std::string path = SpeechPath("sense_and_sensibility_01_austen_64kb-0870.wav");
  DecodeOptions options;
  options.limits.max_duration_s = 1.0;
  auto result = DecodeAudioFile(path, options);
  ExpectInvalid(result,
                "audio.duration_s: 7.100 s (113600 frames at 16000 Hz) exceeds the limit of 1 s "
                "(limits.max_duration_s)");
  EXPECT_THAT(std::string(result.status().message()), StartsWith(path + ": "));

  options = {};
  options.limits.min_sample_rate_hz = 22050;
  ExpectInvalid(DecodeAudioFile(path, options),
                "audio.sample_rate_hz: 16000 is not a supported rate (22050..192000 Hz");

  options = {};
  options.limits.max_bytes = 1000;
  ExpectInvalid(DecodeAudioFile(path, options),
                "audio.bytes: 227244 bytes exceed the limit of 1000 bytes (limits.max_bytes)");
  ExpectInvalid(Decode(ClipBytes(), options), "audio.bytes: 95724 bytes exceed the limit of 1000");

  options = {};
  options.limits.max_channels = 1;
  auto mono = DecodeAudioFile(path);
  ASSERT_TRUE(mono.ok());
  auto stereo = EncodeWav(testing::Interleave({mono->samples, mono->samples}), 16000, 2,
                          WavSampleFormat::kPcm16);
  ASSERT_TRUE(stereo.ok());
  ExpectInvalid(Decode(*stereo, options), "audio.channels: 2 exceeds the limit of 1");
}

TEST(DecodeErrorsTest, InvalidLimits) {
  DecodeOptions options;
  options.limits.max_sample_rate_hz = 4000;
  ExpectInvalid(Decode(ClipBytes(), options),
                "limits.max_sample_rate_hz: 4000 is below limits.min_sample_rate_hz 8000");
  options = {};
  options.limits.max_duration_s = std::numeric_limits<double>::quiet_NaN();
  ExpectInvalid(Decode(ClipBytes(), options), "limits.max_duration_s: must be a finite number > 0");
  options = {};
  options.limits.max_channels = 0;
  ExpectInvalid(Decode(ClipBytes(), options), "limits.max_channels: must be >= 1, got 0");
}

TEST(DecodeErrorsTest, MissingFileAndDirectory) {
  auto missing = DecodeAudioFile("/nonexistent/kinemo/x.wav");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(missing.status().message(), "/nonexistent/kinemo/x.wav: no such file");
  auto directory = DecodeAudioFile(std::string(KINEMO_TEST_DATA_DIR));
  ASSERT_FALSE(directory.ok());
  EXPECT_THAT(directory.status().message(), HasSubstr("not a regular file"));
}

TEST(DecodeErrorsTest, NotAWavAtAll) {
  ExpectInvalid(DecodeAudioFile(SpeechPath("transcription")),
                "transcription: audio: cannot decode 634 bytes starting with '<s> '");
}

// Every prefix of the header region and a sweep of single-byte corruptions:
// each gives a result or an error, never a crash (run under ASan/UBSan in CI
// builds that enable them).
TEST(DecodeErrorsTest, CorruptionSweepNeverCrashes) {
  const auto full = ClipBytes();
  int errors = 0;
  for (std::size_t n = 0; n <= 128; ++n) {
    const std::vector<std::uint8_t> cut(full.begin(), full.begin() + n);
    errors += Decode(cut).ok() ? 0 : 1;
  }
  EXPECT_EQ(errors, 129);  // every prefix is truncated
  for (std::size_t at = 0; at < 48; ++at) {
    for (std::uint8_t value : {0x00, 0x01, 0x7F, 0x80, 0xFF}) {
      auto bytes = full;
      bytes[at] = value;
      auto result = Decode(bytes);
      if (!result.ok()) {
        EXPECT_FALSE(result.status().message().empty());
      } else {
        EXPECT_GT(result->sample_rate_hz, 0);
        EXPECT_LE(result->duration_s, 3600.0);
      }
    }
  }
}

}  // namespace
}  // namespace kinemo::audio
