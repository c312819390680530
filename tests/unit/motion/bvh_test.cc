// BVH reader/writer on the real files in tests/data/motion.
#include "common/motion/bvh.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "tests/unit/motion/motion_test_util.h"

namespace kinemo::motion {
namespace {

using testing::LoadClip;
using testing::MotionDataPath;
using testing::TestFiles;

class BvhFileTest : public ::testing::TestWithParam<testing::TestFile> {};

TEST_P(BvhFileTest, ReadsShape) {
  const testing::TestFile& tf = GetParam();
  const Clip clip = LoadClip(tf.name);
  EXPECT_EQ(clip.skeleton.num_joints(), tf.num_joints);
  EXPECT_EQ(clip.skeleton.num_channels(), tf.num_channels);
  EXPECT_EQ(clip.num_frames(), tf.num_frames);
  EXPECT_EQ(clip.frames.cols(), tf.num_channels);
  EXPECT_DOUBLE_EQ(clip.frame_time_s, tf.frame_time_s);
  EXPECT_NEAR(clip.duration_s(), tf.num_frames * tf.frame_time_s, 1e-12);
  EXPECT_TRUE(clip.Validate().ok());
  // Channel runs are contiguous and in file order.
  int column = 0;
  for (int j = 0; j < clip.skeleton.num_joints(); ++j) {
    EXPECT_EQ(clip.channel_offset(j), column);
    column += clip.skeleton.joint(j).num_channels();
    EXPECT_LT(clip.skeleton.joint(j).parent, j);
  }
  EXPECT_EQ(column, tf.num_channels);
}

// Reading what we wrote gives exactly the same numbers (shortest
// round-trip representation), and the same hierarchy.
TEST_P(BvhFileTest, RoundTripIsExact) {
  const Clip clip = LoadClip(GetParam().name);
  StatusOr<std::string> text = WriteBvh(clip);
  ASSERT_TRUE(text.ok()) << text.status();
  StatusOr<Clip> back = ParseBvh(*text, "written.bvh");
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->skeleton.num_joints(), clip.skeleton.num_joints());
  for (int j = 0; j < clip.skeleton.num_joints(); ++j) {
    const Joint& a = clip.skeleton.joint(j);
    const Joint& b = back->skeleton.joint(j);
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.parent, b.parent);
    EXPECT_EQ(a.channels, b.channels) << a.name;
    EXPECT_EQ(a.offset, b.offset) << a.name;
    EXPECT_EQ(a.end_site.has_value(), b.end_site.has_value()) << a.name;
    if (a.end_site && b.end_site) {
      EXPECT_EQ(*a.end_site, *b.end_site);
    }
  }
  EXPECT_EQ(back->frame_time_s, clip.frame_time_s);
  ASSERT_EQ(back->frames.rows(), clip.frames.rows());
  ASSERT_EQ(back->frames.cols(), clip.frames.cols());
  EXPECT_EQ((back->frames - clip.frames).cwiseAbs().maxCoeff(), 0.0);
}

// The verification interface: within 1e-4 also with fewer digits, and via a file.
TEST_P(BvhFileTest, RoundTripWithNineDigitsThroughFileWithin1e4) {
  const Clip clip = LoadClip(GetParam().name);
  const std::string path = testing::TempPath("out.bvh");
  BvhWriteOptions options;
  options.significant_digits = 9;
  ASSERT_TRUE(WriteBvhFile(clip, path, options).ok());
  StatusOr<Clip> back = ReadBvhFile(path);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->frames.rows(), clip.frames.rows());
  EXPECT_LE((back->frames - clip.frames).cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_NEAR(back->frame_time_s, clip.frame_time_s, 1e-12);
}

INSTANTIATE_TEST_SUITE_P(RealFiles, BvhFileTest, ::testing::ValuesIn(TestFiles()),
                         [](const ::testing::TestParamInfo<testing::TestFile>& info) {
                           std::string n;
                           for (char c : info.param.name)
                             n += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
                           return n;
                         });

TEST(BvhReaderTest, BandaiHasPositionChannelsOnEveryJoint) {
  const Clip clip = LoadClip("dataset-1_bye_normal_001.bvh");
  const Skeleton& sk = clip.skeleton;
  EXPECT_EQ(sk.joint(0).name, "joint_Root");
  EXPECT_EQ(sk.num_end_sites(), 5);
  for (const Joint& j : sk.joints()) {
    ASSERT_EQ(j.num_channels(), 6) << j.name;
    EXPECT_TRUE(j.has_position_channels());
    EXPECT_TRUE(j.has_euler_rotation());
    // Xposition Yposition Zposition Zrotation Xrotation Yrotation
    EXPECT_EQ(j.rotation_axis, (std::array<int, 3>{2, 0, 1})) << j.name;
  }
  const int hips = sk.FindJoint("Hips");
  ASSERT_GE(hips, 0);
  EXPECT_NEAR(sk.joint(hips).offset.y(), 93.9915, 1e-12);
}

TEST(BvhReaderTest, CmuIcloneChannelOrderAndEndSites) {
  const Clip clip = LoadClip("cmu_002_03.bvh");
  const Skeleton& sk = clip.skeleton;
  EXPECT_EQ(sk.joint(0).name, "RL_BoneRoot");
  EXPECT_EQ(sk.joint(0).num_channels(), 6);
  for (int j = 1; j < sk.num_joints(); ++j) {
    EXPECT_EQ(sk.joint(j).num_channels(), 3);
    EXPECT_FALSE(sk.joint(j).has_position_channels());
    EXPECT_EQ(sk.joint(j).rotation_axis, (std::array<int, 3>{2, 1, 0}));  // Z Y X
  }
  const int hip = sk.FindJoint("CC_Base_Hip");
  ASSERT_EQ(hip, 1);
  EXPECT_NEAR(sk.joint(hip).offset.z(), 105.214241, 1e-12);
  EXPECT_GT(sk.num_end_sites(), 20);
}

TEST(BvhReaderTest, Cmu31WithCrlfAndTabs) {
  const std::string text = testing::ReadFileOrDie(MotionDataPath("131_01.bvh"));
  ASSERT_NE(text.find("\r\n"), std::string::npos);  // the real file has CRLF lines
  ASSERT_NE(text.find('\t'), std::string::npos);
  const Clip clip = LoadClip("131_01.bvh");
  EXPECT_EQ(clip.skeleton.FindJoint("LeftWrist"), 20);
  EXPECT_EQ(clip.skeleton.num_end_sites(), 7);
  // Mixed channel orders in one file: legs/spine Z Y X, arms Z X Y.
  EXPECT_EQ(clip.skeleton.joint(clip.skeleton.FindJoint("LeftKnee")).rotation_axis,
            (std::array<int, 3>{2, 1, 0}));
  EXPECT_EQ(clip.skeleton.joint(clip.skeleton.FindJoint("LeftShoulder")).rotation_axis,
            (std::array<int, 3>{2, 0, 1}));
  EXPECT_NEAR(clip.fps(), 120.0, 0.01);
  // First value of the first frame ("5.2300") and last of the last frame.
  EXPECT_DOUBLE_EQ(clip.frames(0, 0), 5.23);
}

// Whitespace variants of a real file (all tabs, CRLF everywhere, extra blank
// lines and trailing spaces, LF-only) all read to the same clip.
TEST(BvhReaderTest, WhitespaceVariantsOfRealFileReadTheSame) {
  const std::string original =
      testing::ReadFileOrDie(MotionDataPath("dataset-1_bye_normal_001.bvh"));
  const Clip ref = LoadClip("dataset-1_bye_normal_001.bvh");
  std::string crlf, tabs, spaced;
  for (char c : original) {
    if (c == '\n') {
      crlf += "\r\n";
      spaced += "   \n\n";
    } else {
      crlf += c;
      spaced += c;
    }
    tabs += (c == ' ') ? '\t' : c;
  }
  for (const std::string* text : {&crlf, &tabs, &spaced}) {
    StatusOr<Clip> clip = ParseBvh(*text, "variant.bvh");
    ASSERT_TRUE(clip.ok()) << clip.status();
    EXPECT_EQ(clip->skeleton.num_joints(), ref.skeleton.num_joints());
    EXPECT_EQ(clip->frames, ref.frames);
  }
}

TEST(BvhWriterTest, RejectsInvalidClip) {
  Clip clip = LoadClip("cmu_007_12_first40.bvh");
  clip.frame_time_s = 0.0;
  EXPECT_FALSE(WriteBvh(clip).ok());
  clip.frame_time_s = 1.0 / 60;
  clip.frames(3, 7) = std::nan("");
  EXPECT_FALSE(WriteBvh(clip).ok());
}

TEST(BvhWriterTest, KeepsChannelOrderAndNames) {
  const Clip clip = LoadClip("dataset-1_bye_normal_001.bvh");
  StatusOr<std::string> text = WriteBvh(clip);
  ASSERT_TRUE(text.ok());
  EXPECT_THAT(*text, ::testing::HasSubstr("ROOT joint_Root\n"));
  EXPECT_THAT(*text,
              ::testing::HasSubstr(
                  "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"));
  EXPECT_THAT(*text, ::testing::HasSubstr("Frames: 111\nFrame Time: 0.0333333\n"));
}

// BvhTextWriter's pieces, of any size, concatenated are WriteBvh's text
// (shortest and 9-digit numbers); each piece is at least max_bytes unless
// it is the last, and whole lines.
TEST_P(BvhFileTest, PiecesMakeTheSameText) {
  const Clip clip = LoadClip(GetParam().name);
  for (int digits : {0, 9}) {
    const BvhWriteOptions options{.significant_digits = digits};
    StatusOr<std::string> whole = WriteBvh(clip, options);
    ASSERT_TRUE(whole.ok());
    for (std::size_t max_bytes : {std::size_t{1}, std::size_t{1000}, std::size_t{65536}, whole->size() * 2}) {
      StatusOr<BvhTextWriter> writer = BvhTextWriter::Create(clip, options);
      ASSERT_TRUE(writer.ok());
      std::string joined, piece;
      int pieces = 0;
      while (true) {
        piece.clear();
        if (!writer->Next(max_bytes, &piece)) break;
        ++pieces;
        ASSERT_FALSE(piece.empty());
        EXPECT_EQ(piece.back(), '\n');
        if (!writer->done()) {
          EXPECT_GE(piece.size(), std::min(max_bytes, whole->size()));
        }
        joined += piece;
      }
      EXPECT_TRUE(writer->done());
      EXPECT_EQ(writer->frames_written(), clip.num_frames());
      EXPECT_EQ(joined, *whole) << "max_bytes " << max_bytes;
      if (max_bytes == 1) {
        EXPECT_EQ(pieces, 1 + clip.num_frames());  // the header, then a frame per piece
      }
      if (max_bytes > whole->size()) {
        EXPECT_EQ(pieces, 1);
      }
      piece.clear();
      EXPECT_FALSE(writer->Next(max_bytes, &piece));
      EXPECT_TRUE(piece.empty());
    }
  }
}

TEST(BvhWriterTest, PiecesRefuseWhatWriteBvhRefuses) {
  Clip clip = LoadClip("cmu_007_12_first40.bvh");
  clip.frames(3, 7) = std::nan("");
  EXPECT_FALSE(BvhTextWriter::Create(clip).ok());
}

}  // namespace
}  // namespace kinemo::motion
