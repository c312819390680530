// `kinemo prosody FILE --json` as a user runs it, on LibriVox speech of
// tests/data/speech: the output does not depend on --threads, and
// --recognize adds words, timed phones and recognizer_rtf.
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/testing/process.h"

namespace {

using kinemo::testing::ChildProcess;
using Json = nlohmann::json;

const std::string kClip =
    std::string(KINEMO_TEST_DATA_DIR) + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";
const std::string kKinemo = std::string(KINEMO_BINARY_DIR) + "/services/cli/kinemo";

// Runs the CLI to its end; its output (stdout and stderr) in `out`.
int Kinemo(std::vector<std::string> args, const std::string& log, std::string* out) {
  args.insert(args.begin(), kKinemo);
  auto rc = ChildProcess::Run(args, log, std::chrono::minutes(5), out);
  EXPECT_TRUE(rc.ok()) << rc.status();
  return rc.ok() ? *rc : -1;
}

TEST(ProsodyCli, JsonIsTheSameOnAnyNumberOfThreads) {
  kinemo::testing::TempDir dir;
  std::string one, three;
  ASSERT_EQ(Kinemo({"prosody", kClip, "--json", "--threads", "1"}, dir.File("1.log"), &one), 0) << one;
  ASSERT_EQ(Kinemo({"prosody", kClip, "--json", "--threads", "3"}, dir.File("3.log"), &three), 0) << three;
  EXPECT_EQ(one, three);
  const Json j = Json::parse(one);
  EXPECT_GT(j["frames"].size(), 700u);
  EXPECT_FALSE(j.contains("recognizer_rtf"));
  std::string bad;
  EXPECT_EQ(Kinemo({"prosody", kClip, "--json", "--threads", "-2"}, dir.File("bad.log"), &bad), 2) << bad;
  EXPECT_NE(bad.find("threads"), std::string::npos) << bad;
}

TEST(ProsodyCli, RecognizePrintsPhonesAndTheRecognizerSpeed) {
  kinemo::testing::TempDir dir;
  std::string out;
  ASSERT_EQ(Kinemo({"prosody", kClip, "--recognize", "--json"}, dir.File("log"), &out), 0) << out;
  const Json j = Json::parse(out);
  ASSERT_TRUE(j["recognizer_ran"].get<bool>());
  ASSERT_TRUE(j.contains("recognizer_rtf"));
  EXPECT_GT(j["recognizer_rtf"].get<double>(), 0.0);
  EXPECT_GE(j["words"].size(), 15u);
  const Json& phones = j["phones"];
  ASSERT_GT(phones.size(), 40u);
  for (std::size_t i = 1; i < phones.size(); ++i) {
    EXPECT_NEAR(phones[i]["start_s"].get<double>(), phones[i - 1]["end_s"].get<double>(), 0.011);
  }
}

}  // namespace
