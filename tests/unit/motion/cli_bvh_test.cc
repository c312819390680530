// `kinemo bvh info|convert` driven in-process through CLI11.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <CLI/CLI.hpp>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/motion/bvh.h"
#include "services/cli/commands.h"
#include "tests/unit/motion/motion_test_util.h"

namespace kinemo::motion {
namespace {

using ::testing::HasSubstr;

struct RunResult {
  int exit_code;
  std::string out;
  std::string err;
};

RunResult RunKinemo(std::vector<std::string> args) {
  CLI::App app{"kinemo"};
  app.require_subcommand(1);
  cli::RegisterBvhCommands(app);
  std::vector<const char*> argv = {"kinemo"};
  for (const std::string& a : args) argv.push_back(a.c_str());
  ::testing::internal::CaptureStdout();
  ::testing::internal::CaptureStderr();
  int code = 0;
  try {
    app.parse(static_cast<int>(argv.size()), argv.data());
  } catch (const CLI::ParseError& e) {
    code = app.exit(e) == 0 ? 0 : 2;
  } catch (const cli::CliExit& e) {
    code = e.code;
  }
  RunResult r;
  r.exit_code = code;
  r.out = ::testing::internal::GetCapturedStdout();
  r.err = ::testing::internal::GetCapturedStderr();
  return r;
}

TEST(CliBvhTest, InfoText) {
  const RunResult r = RunKinemo({"bvh", "info", testing::MotionDataPath("131_01.bvh")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("skeleton:    cmu31"));
  EXPECT_THAT(r.out, HasSubstr("joints:      31 (+7 end sites)"));
  EXPECT_THAT(r.out, HasSubstr("frames:      994"));
  EXPECT_THAT(r.out, HasSubstr("LeftWrist  [left_hand] 3 ch: Zrotation Xrotation Yrotation"));
}

TEST(CliBvhTest, InfoJson) {
  const RunResult r =
      RunKinemo({"bvh", "info", "--json", testing::MotionDataPath("cmu_002_03.bvh")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["skeleton_family"], "cmu_iclone100");
  EXPECT_EQ(j["num_frames"], 86);
  EXPECT_EQ(j["num_joints"], static_cast<int>(j["joints"].size()));
  EXPECT_NEAR(j["fps"].get<double>(), 60.0, 0.01);
  EXPECT_NEAR(j["duration_s"].get<double>(), 86 * 0.016667, 1e-9);
  EXPECT_EQ(j["joints"][0]["name"], "RL_BoneRoot");
  EXPECT_EQ(j["joints"][0]["channels"].size(), 6u);
}

TEST(CliBvhTest, ConvertRoundTripAndResample) {
  const std::string in = testing::MotionDataPath("dataset-1_bye_normal_001.bvh");
  const std::string out = testing::TempPath("out.bvh");
  RunResult r = RunKinemo({"bvh", "convert", in, "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  StatusOr<Clip> a = ReadBvhFile(in);
  StatusOr<Clip> b = ReadBvhFile(out);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->frames, b->frames);

  const std::string out60 = testing::TempPath("out60.bvh");
  r = RunKinemo({"bvh", "convert", in, "--out", out60, "--fps", "60"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  StatusOr<Clip> c = ReadBvhFile(out60);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->num_frames(), 2 * a->num_frames() - 1);
  EXPECT_NEAR(c->fps(), 60.0, 1e-9);

  // The old spelling (OUT as a second argument) still works, with a note.
  const std::string old = testing::TempPath("old.bvh");
  r = RunKinemo({"bvh", "convert", in, old});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, HasSubstr("bvh convert IN OUT is deprecated"));
  EXPECT_THAT(r.err, HasSubstr("use bvh convert IN -o OUT"));
  StatusOr<Clip> d = ReadBvhFile(old);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(a->frames, d->frames);
  // Without an output: usage, naming the option.
  r = RunKinemo({"bvh", "convert", in});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("-o/--out: is required"));
}

TEST(CliBvhTest, ErrorsGoToStderrWithNonZeroExit) {
  // A truncated copy of a real file.
  const std::string bad = testing::TempPath("truncated.bvh");
  {
    const std::string text = testing::ReadFileOrDie(testing::MotionDataPath("131_01.bvh"));
    std::ofstream f(bad, std::ios::binary);
    f << text.substr(0, text.size() / 3);
  }
  RunResult r = RunKinemo({"bvh", "info", bad});
  EXPECT_EQ(r.exit_code, 2);  // bad input
  EXPECT_THAT(r.err, HasSubstr(bad + ":"));
  EXPECT_THAT(r.err, HasSubstr("values, expected 96 (file ends)"));
  EXPECT_EQ(r.out, "");

  const std::string empty = testing::TempPath("empty.bvh");
  { std::ofstream f(empty); }
  r = RunKinemo({"bvh", "convert", empty, "-o", testing::TempPath("x.bvh")});
  EXPECT_EQ(r.exit_code, 2);  // bad input
  EXPECT_THAT(r.err, HasSubstr("empty file"));

  r = RunKinemo({"bvh", "convert", testing::MotionDataPath("131_01.bvh"), "-o",
                 testing::TempPath("y.bvh"), "--fps", "-3"});
  EXPECT_EQ(r.exit_code, 2);  // usage

  r = RunKinemo(
      {"bvh", "convert", testing::MotionDataPath("131_01.bvh"), "-o", "/nonexistent/dir/out.bvh"});
  EXPECT_EQ(r.exit_code, 1);  // cannot write the output
  EXPECT_THAT(r.err, HasSubstr("/nonexistent/dir/out.bvh"));
}

}  // namespace
}  // namespace kinemo::motion
