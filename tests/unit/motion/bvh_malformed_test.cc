// Malformed BVH inputs built from the real files: truncated, garbled,
// unbalanced, absurd sizes. Every case must give an error naming the line,
// never a crash.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <string>

#include "common/motion/bvh.h"
#include "tests/unit/motion/motion_test_util.h"

namespace kinemo::motion {
namespace {

using ::testing::HasSubstr;
using testing::MotionDataPath;
using testing::ReadFileOrDie;

constexpr char kName[] = "bad.bvh";

int LineOf(const std::string& text, size_t pos) {
  return 1 +
         static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(pos), '\n'));
}

std::string LinePrefix(int line) { return std::string(kName) + ":" + std::to_string(line) + ":"; }

// Replaces the first occurrence of `from` (after `start`) and returns the
// position of the replacement.
size_t ReplaceFirst(std::string* text, const std::string& from, const std::string& to,
                    size_t start = 0) {
  const size_t pos = text->find(from, start);
  EXPECT_NE(pos, std::string::npos) << from;
  if (pos != std::string::npos) text->replace(pos, from.size(), to);
  return pos;
}

// Expects an INVALID_ARGUMENT error whose message starts with "bad.bvh:<line>:"
// and contains `what`. Returns the message.
std::string ExpectError(const std::string& text, int line, const std::string& what,
                        const BvhReadOptions& options = {}) {
  StatusOr<Clip> clip = ParseBvh(text, kName, options);
  EXPECT_FALSE(clip.ok());
  if (clip.ok()) return "";
  const std::string msg(clip.status().message());
  EXPECT_EQ(clip.status().code(), absl::StatusCode::kInvalidArgument) << msg;
  if (line > 0) {
    EXPECT_EQ(msg.rfind(LinePrefix(line), 0), 0u) << msg;
  }
  EXPECT_THAT(msg, HasSubstr(what));
  return msg;
}

class MalformedTest : public ::testing::Test {
 protected:
  void SetUp() override {
    bandai_ = ReadFileOrDie(MotionDataPath("dataset-1_bye_normal_001.bvh"));
    cmu31_ = ReadFileOrDie(MotionDataPath("131_01.bvh"));
    iclone_ = ReadFileOrDie(MotionDataPath("cmu_007_12_first40.bvh"));
  }
  std::string bandai_, cmu31_, iclone_;
};

TEST_F(MalformedTest, EmptyInputs) {
  ExpectError("", 1, "empty file");
  ExpectError(" \r\n\t\n", 3, "empty file");
}

// The real 0-byte file of the shared data set (dataset-1_dance-long_normal_001.bvh)
// is reproduced here as an empty file on disk.
TEST_F(MalformedTest, EmptyFileOnDisk) {
  const std::string path = testing::TempPath("dataset-1_dance-long_normal_001.bvh");
  { std::ofstream f(path, std::ios::binary | std::ios::trunc); }
  StatusOr<Clip> clip = ReadBvhFile(path);
  ASSERT_FALSE(clip.ok());
  EXPECT_THAT(std::string(clip.status().message()), HasSubstr(path + ":1: empty file"));
}

TEST_F(MalformedTest, MissingFileAndDirectory) {
  EXPECT_EQ(ReadBvhFile("/nonexistent/dir/x.bvh").status().code(), absl::StatusCode::kNotFound);
  EXPECT_FALSE(ReadBvhFile(KINEMO_TEST_DATA_DIR).ok());
}

// Truncating each real file at many points gives an error with a line
// number, never a crash or a silently shorter clip.
TEST_F(MalformedTest, TruncatedAnywhere) {
  for (const std::string* text : {&bandai_, &cmu31_, &iclone_}) {
    // Cuts inside the last line could leave a valid shorter last number.
    std::string trimmed = *text;
    while (!trimmed.empty() && std::isspace(static_cast<unsigned char>(trimmed.back())))
      trimmed.pop_back();
    const size_t last_line = trimmed.rfind('\n');
    ASSERT_NE(last_line, std::string::npos);
    constexpr int kCuts = 300;
    for (int k = 0; k < kCuts; ++k) {
      const size_t cut = 1 + (last_line - 1) * static_cast<size_t>(k) / kCuts;
      const std::string truncated = text->substr(0, cut);
      StatusOr<Clip> clip = ParseBvh(truncated, kName);
      ASSERT_FALSE(clip.ok()) << "cut at " << cut;
      const std::string msg(clip.status().message());
      EXPECT_THAT(msg, ::testing::MatchesRegex("bad\\.bvh:[0-9]+: .*")) << msg;
    }
  }
}

TEST_F(MalformedTest, TruncatedMidFrameNamesLineAndCount) {
  const size_t motion = cmu31_.find("MOTION");
  // Cut in the middle of the 4th frame line (line of MOTION + 3 header lines).
  size_t pos = motion;
  for (int i = 0; i < 6; ++i) pos = cmu31_.find('\n', pos) + 1;
  const std::string cut = cmu31_.substr(0, pos + 40);
  const std::string msg = ExpectError(cut, LineOf(cmu31_, pos), "frame 3 has");
  EXPECT_THAT(msg, HasSubstr("expected 96"));
}

TEST_F(MalformedTest, TruncatedAtLineBoundaryReportsFrameCount) {
  const size_t motion = cmu31_.find("MOTION");
  size_t pos = motion;
  for (int i = 0; i < 13; ++i) pos = cmu31_.find('\n', pos) + 1;  // 10 full frames
  ExpectError(cmu31_.substr(0, pos), 0, "file ends after 10 of 994 frames");
}

TEST_F(MalformedTest, MissingMotion) {
  const size_t motion = bandai_.find("MOTION");
  ExpectError(bandai_.substr(0, motion), LineOf(bandai_, motion), "missing MOTION");
}

TEST_F(MalformedTest, GarbledTokens) {
  {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, "OFFSET 15.7357 0 0", "OFSET 15.7357 0 0");
    ExpectError(t, LineOf(t, pos), "unexpected token 'OFSET'");
  }
  {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, "OFFSET 15.7357 0 0", "OFFSET 15.7x357 0 0");
    ExpectError(t, LineOf(t, pos), "expected a number, got '15.7x357'");
  }
  {
    std::string t = cmu31_;
    const size_t pos = ReplaceFirst(&t, "Zrotation", "Zrot@tion");
    ExpectError(t, LineOf(t, pos), "unknown channel 'Zrot@tion'");
  }
  {
    std::string t = cmu31_;
    const size_t pos = ReplaceFirst(&t, "JOINT LeftKnee", "JOINT");
    ExpectError(t, LineOf(t, pos), "JOINT without a name");
  }
  {
    // A garbled number in frame 2 of the motion.
    std::string t = iclone_;
    size_t pos = t.find("MOTION");
    for (int i = 0; i < 5; ++i) pos = t.find('\n', pos) + 1;  // start of frame 2
    const size_t space = t.find(' ', pos + 1);
    t.replace(space + 1, 3, "1.2.3");
    ExpectError(t, LineOf(t, pos), "frame 2 value 1: expected a finite number");
  }
  for (const std::string bad : {"nan", "inf", "-", "0x1p3", "1e999", "\x01\xff"}) {
    std::string t = iclone_;
    size_t pos = t.find("MOTION");
    for (int i = 0; i < 3; ++i) pos = t.find('\n', pos) + 1;  // start of frame 0
    const size_t space = t.find(' ', pos);
    t.replace(pos, space - pos, bad);
    ExpectError(t, LineOf(t, pos), "frame 0 value 0: expected a finite number");
  }
  {
    std::string t = bandai_;
    t.replace(0, 9, "HIERARHY");
    ExpectError(t, 1, "expected 'HIERARCHY'");
  }
  {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, "Frame Time:", "Frame Tim:");
    ExpectError(t, LineOf(t, pos), "expected 'Frame Time:'");
  }
}

TEST_F(MalformedTest, UnbalancedBraces) {
  {
    // Drop the '}' closing the first End Site: its OFFSET line is then followed by '}' of Head...
    std::string t = cmu31_;
    const size_t pos = t.rfind('}', t.find("MOTION"));
    t.erase(pos, 1);
    ExpectError(t, LineOf(t, t.find("MOTION")), "MOTION inside joint 'Hips'");
  }
  {
    std::string t = cmu31_;
    const size_t motion = t.find("MOTION");
    t.insert(motion, "}\r\n");
    ExpectError(t, LineOf(t, motion), "unbalanced '}'");
  }
  {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, "JOINT Spine\n    {\n", "JOINT Spine\n    {\n {\n");
    ExpectError(t, LineOf(t, pos) + 2, "unexpected '{'");
  }
  {
    // Hierarchy only, cut before its last '}'.
    std::string t = bandai_.substr(0, bandai_.rfind('}', bandai_.find("MOTION")));
    ExpectError(t, 0, "file ends inside joint 'joint_Root' opened at line 2");
  }
}

TEST_F(MalformedTest, WrongNumberOfValuesPerFrame) {
  std::string t = bandai_;
  size_t pos = t.find("MOTION");
  for (int i = 0; i < 8; ++i) pos = t.find('\n', pos) + 1;  // start of frame 5
  const size_t eol = t.find('\n', pos);
  {
    std::string fewer = t;
    size_t end = eol;
    while (fewer[end - 1] == ' ') --end;  // the real lines end with a space
    const size_t last_space = fewer.rfind(' ', end - 1);
    fewer.erase(last_space, end - last_space);
    ExpectError(fewer, LineOf(t, pos), "frame 5 has 131 values, expected 132");
  }
  {
    std::string more = t;
    more.insert(eol, " 1.5");
    ExpectError(more, LineOf(t, pos), "frame 5 has more than 132 values");
  }
}

TEST_F(MalformedTest, FrameCountMismatch) {
  {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, "Frames:\t111", "Frames:\t112");
    ExpectError(t, 0,
                "file ends after 111 of 112 frames declared by Frames: at line " +
                    std::to_string(LineOf(t, pos)));
  }
  {
    std::string t = bandai_;
    ReplaceFirst(&t, "Frames:\t111", "Frames:\t110");
    ExpectError(t, LineOf(t, t.size() - 2), "data after the 110 frames");
  }
}

TEST_F(MalformedTest, AbsurdSizes) {
  const auto with = [this](const std::string& from, const std::string& to) {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, from, to);
    return std::make_pair(t, LineOf(t, pos));
  };
  {
    auto [t, line] = with("Frames:\t111", "Frames:\t99999999999");
    ExpectError(t, line, "exceeds max_frames=10000000");
  }
  {
    auto [t, line] = with("Frames:\t111", "Frames:\t999999999999999999999999");
    ExpectError(t, line, "exceeds max_frames");
  }
  {
    auto [t, line] = with("Frames:\t111", "Frames:\t-5");
    ExpectError(t, line, "is negative");
  }
  {
    // Plausible count, short file: only what the file can hold is allocated.
    auto [t, line] = with("Frames:\t111", "Frames:\t1000000");
    ExpectError(t, 0,
                "file ends after 111 of 1000000 frames declared by Frames: at line " +
                    std::to_string(line));
  }
  {
    auto [t, line] = with("Frames:\t111", "Frames:\t3000000");
    BvhReadOptions options;
    options.max_values = 1000000;
    ExpectError(t, line, "exceeds max_values=1000000", options);
  }
  for (const std::string bad : {"0", "-0.0333", "nan", "NaN", "inf", "1e400", "abc", "1e5"}) {
    auto [t, line] = with("Frame Time:\t0.0333333", "Frame Time:\t" + bad);
    ExpectError(t, line, "Frame Time:");
  }
  {
    auto [t, line] = with("CHANNELS 6 Xposition", "CHANNELS 1000 Xposition");
    ExpectError(t, line, "CHANNELS 1000: a joint has 0..6 channels");
  }
  {
    auto [t, line] = with("CHANNELS 6 Xposition", "CHANNELS -1 Xposition");
    ExpectError(t, line, "a joint has 0..6 channels");
  }
  {
    BvhReadOptions options;
    options.max_joints = 10;
    ExpectError(bandai_, LineOf(bandai_, bandai_.find("JOINT Shoulder_R")),
                "more than max_joints=10", options);
  }
  {
    BvhReadOptions options;
    options.max_file_bytes = 1000;
    ExpectError(bandai_, 1, "exceeds max_file_bytes=1000", options);
    const std::string path = MotionDataPath("dataset-1_bye_normal_001.bvh");
    StatusOr<Clip> clip = ReadBvhFile(path, options);
    ASSERT_FALSE(clip.ok());
    EXPECT_THAT(std::string(clip.status().message()), HasSubstr("max_file_bytes=1000"));
  }
  {
    BvhReadOptions options;
    options.max_nesting_depth = 3;
    ExpectError(bandai_, LineOf(bandai_, bandai_.find("JOINT Chest")), "max_nesting_depth=3",
                options);
  }
}

TEST_F(MalformedTest, DuplicateNamesAndRepeatedSections) {
  {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, "JOINT Spine", "JOINT Hips");
    ExpectError(t, LineOf(t, pos), "duplicate joint name 'Hips' (first at line 6)");
  }
  {
    std::string t = bandai_;
    const size_t pos = ReplaceFirst(&t, "OFFSET 15.7357 0 0", "OFFSET 15.7357 0 0\nOFFSET 1 2 3");
    ExpectError(t, LineOf(t, pos) + 1, "second OFFSET");
  }
  {
    std::string t = cmu31_;
    const size_t pos = ReplaceFirst(&t, "CHANNELS 3 Zrotation Yrotation Xrotation",
                                    "CHANNELS 4 Zrotation Yrotation Xrotation Zrotation");
    ExpectError(t, LineOf(t, pos), "more than 3 rotation channels");
  }
  {
    std::string t = cmu31_;
    const size_t pos =
        ReplaceFirst(&t, "CHANNELS 6 Xposition Yposition", "CHANNELS 6 Xposition Xposition");
    ExpectError(t, LineOf(t, pos), "Xposition listed twice");
  }
}

}  // namespace
}  // namespace kinemo::motion
