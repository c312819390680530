// RecordingReader (a file read block by block, mono, resampled) and
// RecordingWriter (long recordings written block by block) on real speech:
// the reader gives what DecodeAudioFile + Resample give, at any rate,
// channel count and container; its errors name the file and say what is
// wrong in the user's words.
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/audio/decode.h"
#include "common/audio/recording_reader.h"
#include "common/audio/recording_writer.h"
#include "common/audio/resample.h"
#include "tests/unit/audio/audio_test_util.h"

namespace kinemo::audio {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;
using testing::SpeechPath;

const std::string kRecordingClip = "sense_and_sensibility_01_austen_64kb-0870.wav";  // 7.1 s, 16 kHz mono

// Everything the reader gives, in blocks of `block` input frames.
StatusOr<std::vector<float>> ReadRecording(const std::string& path, int rate_hz, std::int64_t block,
                                     RecordingInfo* info = nullptr) {
  KINEMO_ASSIGN_OR_RETURN(auto reader, RecordingReader::Open(path, rate_hz));
  if (info != nullptr) *info = reader->info();
  std::vector<float> out;
  while (true) {
    KINEMO_ASSIGN_OR_RETURN(bool more, reader->Read(block, &out));
    if (!more) break;
  }
  return out;
}

TEST(RecordingReaderTest, A16kHzFileIsItsSamples) {
  auto decoded = DecodeAudioFile(SpeechPath(kRecordingClip));
  ASSERT_TRUE(decoded.ok());
  for (std::int64_t block : {1, 1000, 1 << 20}) {
    RecordingInfo info;
    auto read = ReadRecording(SpeechPath(kRecordingClip), 16000, block, &info);
    ASSERT_TRUE(read.ok()) << read.status();
    EXPECT_EQ(*read, decoded->samples) << "block " << block;
    EXPECT_EQ(info.format, "wav");
    EXPECT_EQ(info.sample_rate_hz, 16000);
    EXPECT_EQ(info.channels, 1);
    EXPECT_NEAR(info.duration_s, 7.1, 1e-3);
  }
}

// The clip as a 44.1 kHz stereo file (the right channel 0.9 of the left) in
// each container: read at 16 kHz it is the mono mix resampled as Resample()
// does (WAV, FLAC exactly up to float rounding; the lossy codecs close).
TEST(RecordingReaderTest, AnyRateChannelsAndContainerComeBackAt16kHzMono) {
  auto decoded = DecodeAudioFile(SpeechPath(kRecordingClip));
  ASSERT_TRUE(decoded.ok());
  auto up = Resample(decoded->samples, 16000, 44100);
  ASSERT_TRUE(up.ok());
  std::vector<float> right(up->size());
  for (std::size_t i = 0; i < up->size(); ++i) right[i] = 0.9f * (*up)[i];
  const std::vector<float> stereo = testing::Interleave({*up, right});
  std::vector<float> mono(up->size());
  for (std::size_t i = 0; i < up->size(); ++i) mono[i] = 0.5f * ((*up)[i] + right[i]);
  auto expected = Resample(mono, 44100, 16000);
  ASSERT_TRUE(expected.ok());
  testing::TempDir dir;
  for (const char* ext : {".wav", ".flac", ".ogg", ".mp3"}) {
    SCOPED_TRACE(ext);
    const std::string path = dir.File(std::string("speech") + ext);
    auto w = RecordingWriter::Create(path, 44100, 2);
    ASSERT_TRUE(w.ok()) << w.status();
    for (std::size_t i = 0; i < stereo.size(); i += 2 * 4410) {  // 0.1 s blocks
      ASSERT_TRUE((*w)->Write({stereo.data() + i, std::min<std::size_t>(2 * 4410, stereo.size() - i)}).ok());
    }
    ASSERT_TRUE((*w)->Close().ok());
    RecordingInfo info;
    auto read = ReadRecording(path, 16000, 4096, &info);
    ASSERT_TRUE(read.ok()) << read.status();
    EXPECT_EQ(info.sample_rate_hz, 44100);
    EXPECT_EQ(info.channels, 2);
    const std::string ext_s = ext;
    if (ext_s == ".wav" || ext_s == ".flac") {
      // 16-bit files: the quantisation (-96 dB) is all that differs.
      EXPECT_EQ(read->size(), expected->size());
      EXPECT_GT(testing::SnrDb(*expected, *read), 60);
    } else {
      // Lossy, and the codec's own delay: the speech is still there.
      EXPECT_NEAR(static_cast<double>(read->size()), static_cast<double>(expected->size()), 0.1 * 16000);
      double best = -1;
      for (int lag = 0; lag <= 1600; lag += 16) {  // up to 0.1 s of codec delay
        if (static_cast<std::size_t>(lag) >= read->size()) break;
        best = std::max(best, testing::Correlation(*expected, std::span<const float>(*read).subspan(lag)));
      }
      EXPECT_GT(best, 0.9);
    }
  }
}

TEST(RecordingReaderTest, ErrorsNameTheFileAndSayWhatIsWrong) {
  testing::TempDir dir;
  {
    auto r = RecordingReader::Open(dir.File("missing.wav"), 16000);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kNotFound);
    EXPECT_EQ(std::string(r.status().message()), dir.File("missing.wav") + ": no such file");
  }
  {
    std::ofstream(dir.File("empty.wav"));
    auto r = RecordingReader::Open(dir.File("empty.wav"), 16000);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(std::string(r.status().message()), dir.File("empty.wav") + ": empty file (0 bytes): there is no recording in it");
  }
  {
    std::ofstream(dir.File("notes.wav")) << "Dear Sir, these are my notes, not a recording.\n";
    auto r = RecordingReader::Open(dir.File("notes.wav"), 16000);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(r.status().message()), StartsWith(dir.File("notes.wav") + ": not an audio file that can be read "
                                                                         "(it starts with 'Dear'"));
    EXPECT_THAT(std::string(r.status().message()), HasSubstr("WAV, FLAC, OGG (Vorbis, Opus), MP3 and AIFF can"));
  }
  {
    // The real clip cut after 20000 bytes.
    auto bytes = testing::ReadBytes(SpeechPath(kRecordingClip));
    bytes.resize(20000);
    std::ofstream(dir.File("cut.wav"), std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), 20000);
    auto r = RecordingReader::Open(dir.File("cut.wav"), 16000);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(r.status().message()), StartsWith(dir.File("cut.wav") + ": truncated WAV: the header declares "));
    EXPECT_THAT(std::string(r.status().message()), HasSubstr("19956 are there (the file was cut short"));
  }
  {
    auto r = RecordingReader::Open(dir.File(""), 16000);  // the folder itself
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(r.status().message()), HasSubstr("is a folder, not an audio file"));
  }
  {
    // Longer than the limit: refused at open, from the header.
    DecodeOptions options;
    options.limits.max_duration_s = 5;
    auto r = RecordingReader::Open(SpeechPath(kRecordingClip), 16000, options);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(std::string(r.status().message()),
              SpeechPath(kRecordingClip) + ": 7 s of audio is longer than the 5 s this accepts; split the recording");
  }
}

TEST(RecordingWriterTest, RefusesAnUnknownExtension) {
  testing::TempDir dir;
  auto w = RecordingWriter::Create(dir.File("x.aac"), 44100, 2);
  EXPECT_EQ(w.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(w.status().message()), HasSubstr("write .wav, .flac, .ogg or .mp3"));
}

}  // namespace
}  // namespace kinemo::audio
