// `kinemo audio info`, run in-process through CLI11 on real speech.
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "common/audio/wav_writer.h"
#include "services/cli/commands.h"
#include "tests/unit/audio/audio_test_util.h"

namespace kinemo::cli {
// The test binary links only cmd_audio.cc; main.cc's other areas are absent.
void RegisterBvhCommands(CLI::App&) {}
}  // namespace kinemo::cli

namespace {

using ::testing::HasSubstr;
using kinemo::audio::testing::SpeechPath;

struct CliRun {
  int code = 0;
  std::string out;
  std::string err;
};

// Mirrors services/cli/main.cc's handling of the exit code.
CliRun Kinemo(std::vector<std::string> args) {
  CLI::App app{"kinemo", "kinemo"};
  app.require_subcommand(1);
  kinemo::cli::RegisterAudioCommands(app);
  std::vector<const char*> argv = {"kinemo"};
  for (const auto& a : args) argv.push_back(a.c_str());
  std::ostringstream out;
  std::ostringstream err;
  auto* old_out = std::cout.rdbuf(out.rdbuf());
  auto* old_err = std::cerr.rdbuf(err.rdbuf());
  CliRun run;
  try {
    app.parse(static_cast<int>(argv.size()), argv.data());
  } catch (const CLI::ParseError& e) {
    run.code = app.exit(e, out, err) == 0 ? 0 : 2;
  } catch (const kinemo::cli::CliExit& e) {
    run.code = e.code;
  }
  std::cout.rdbuf(old_out);
  std::cerr.rdbuf(old_err);
  run.out = out.str();
  run.err = err.str();
  return run;
}

TEST(CliAudioInfoTest, TextOutput) {
  const CliRun run = Kinemo({"audio", "info", SpeechPath("sense_and_sensibility_01_austen_64kb-0870.wav")});
  ASSERT_EQ(run.code, 0) << run.err;
  EXPECT_THAT(run.out, HasSubstr("format:        wav (WAV (Microsoft))"));
  EXPECT_THAT(run.out, HasSubstr("subtype:       pcm_16 (Signed 16 bit PCM)"));
  EXPECT_THAT(run.out, HasSubstr("sample_rate:   16000 Hz"));
  EXPECT_THAT(run.out, HasSubstr("channels:      1"));
  EXPECT_THAT(run.out, HasSubstr("frames:        113600"));
  EXPECT_THAT(run.out, HasSubstr("duration_s:    7.100"));
  EXPECT_THAT(run.out, HasSubstr("peak_dbfs:     -"));
  EXPECT_THAT(run.out, HasSubstr("rms_dbfs:      -"));
}

TEST(CliAudioInfoTest, JsonOutputAgreesWithTheLibrary) {
  const std::string path = SpeechPath("sense_and_sensibility_01_austen_64kb-0880.wav");
  const CliRun run = Kinemo({"audio", "info", path, "--json"});
  ASSERT_EQ(run.code, 0) << run.err;
  const auto j = nlohmann::json::parse(run.out);
  auto audio = kinemo::audio::DecodeAudioFile(path);
  ASSERT_TRUE(audio.ok());
  EXPECT_EQ(j["format"], "wav");
  EXPECT_EQ(j["subtype"], "pcm_16");
  EXPECT_EQ(j["sample_rate_hz"], 16000);
  EXPECT_EQ(j["channels"], 1);
  EXPECT_EQ(j["frames"], 47840);
  EXPECT_DOUBLE_EQ(j["duration_s"].get<double>(), 2.99);
  EXPECT_NEAR(j["peak_dbfs"].get<double>(), kinemo::audio::ToDbfs(audio->peak), 1e-9);
  EXPECT_NEAR(j["rms_dbfs"].get<double>(), kinemo::audio::ToDbfs(audio->rms), 1e-9);
}

TEST(CliAudioInfoTest, StereoFloat48kHz) {
  auto mono = kinemo::audio::DecodeAudioFile(SpeechPath("sense_and_sensibility_01_austen_64kb-0930.wav"));
  ASSERT_TRUE(mono.ok());
  auto up = kinemo::audio::Resample(mono->samples, 16000, 48000);
  ASSERT_TRUE(up.ok());
  kinemo::audio::testing::TempDir dir;
  const std::string path = dir.File("stereo.wav");
  ASSERT_TRUE(kinemo::audio::WriteWavFile(path, kinemo::audio::testing::Interleave({*up, *up}),
                                          48000, 2, kinemo::audio::WavSampleFormat::kFloat32)
                  .ok());
  const CliRun run = Kinemo({"audio", "info", path, "--json"});
  ASSERT_EQ(run.code, 0) << run.err;
  const auto j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["subtype"], "float");
  EXPECT_EQ(j["sample_rate_hz"], 48000);
  EXPECT_EQ(j["channels"], 2);
  EXPECT_NEAR(j["duration_s"].get<double>(), 3.29, 1e-9);
}

TEST(CliAudioInfoTest, RawPcm) {
  const std::string path = SpeechPath("goforward.raw");
  const CliRun run = Kinemo({"audio", "info", path, "--raw-rate", "16000", "--raw-channels", "1",
                          "--raw-encoding", "s16le", "--json"});
  ASSERT_EQ(run.code, 0) << run.err;
  const auto j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["format"], "raw");
  EXPECT_EQ(j["frames"], 44580);
  EXPECT_DOUBLE_EQ(j["duration_s"].get<double>(), 2.78625);

  const CliRun no_rate = Kinemo({"audio", "info", path});
  EXPECT_EQ(no_rate.code, 2);
  EXPECT_THAT(no_rate.err, HasSubstr("--raw-rate"));
  EXPECT_TRUE(no_rate.out.empty());

  const CliRun bad_encoding = Kinemo({"audio", "info", path, "--raw-rate", "16000", "--raw-encoding", "mp3"});
  EXPECT_EQ(bad_encoding.code, 2);
  EXPECT_THAT(bad_encoding.err, HasSubstr("raw.encoding: 'mp3' is not supported"));

  const CliRun odd = Kinemo({"audio", "info", path, "--raw-rate", "16000", "--raw-channels", "7"});  // 89160 % 14 != 0
  EXPECT_EQ(odd.code, 2);
  EXPECT_THAT(odd.err, HasSubstr("trailing byte"));
}

TEST(CliAudioInfoTest, ErrorsGoToStderrWithNonZeroExit) {
  const CliRun missing = Kinemo({"audio", "info", "/nonexistent/x.wav"});
  EXPECT_EQ(missing.code, 2);
  EXPECT_EQ(missing.err, "kinemo audio info: /nonexistent/x.wav: no such file\n");
  EXPECT_TRUE(missing.out.empty());

  const CliRun garbage = Kinemo({"audio", "info", SpeechPath("transcription")});
  EXPECT_EQ(garbage.code, 2);
  EXPECT_THAT(garbage.err, HasSubstr("cannot decode"));

  const CliRun usage = Kinemo({"audio", "info"});
  EXPECT_EQ(usage.code, 2);
}

}  // namespace
