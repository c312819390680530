// Position channels: absolute (replace OFFSET) or displacements (add to it),
// detected per joint from the real files.
#include <gtest/gtest.h>

#include "common/motion/bvh.h"
#include "common/motion/body_regions.h"
#include "common/motion/kinematics.h"
#include "tests/unit/motion/motion_test_util.h"

namespace kinemo::motion {
namespace {

using testing::LoadClip;
using testing::MotionDataPath;

// Lowest world height of the foot/toe joints over the clip, and the root's
// hips' mean height, in file units (cm here).
std::pair<double, double> FootAndHipHeight(const Clip& clip, int hips) {
  const auto key = FindKeyJoints(clip.skeleton, MapBodyRegions(clip.skeleton));
  EXPECT_TRUE(key.ok()) << key.status();
  double foot_min = 1e9, root_sum = 0;
  for (int f = 0; f < clip.num_frames(); ++f) {
    const auto pose = ComputeWorldPose(clip, f);
    EXPECT_TRUE(pose.ok());
    for (int j : {key->left_foot, key->right_foot, key->left_toe, key->right_toe}) {
      if (j >= 0) foot_min = std::min(foot_min, pose->positions[static_cast<size_t>(j)].y());
    }
    root_sum += pose->positions[static_cast<size_t>(hips)].y();
  }
  return {foot_min, root_sum / clip.num_frames()};
}

TEST(PositionChannels, IcloneRootIsADisplacementFromItsOffset) {
  // ROOT CC_Base_Hip: OFFSET y = 105.2 cm, Yposition channel near 0.
  const Clip clip = LoadClip("cmu_007_12_first40.bvh");
  EXPECT_TRUE(clip.skeleton.joint(0).position_relative_to_offset);
  const auto [foot, root] = FootAndHipHeight(clip, 0);
  EXPECT_GT(root, 80.0);   // hips about a metre up
  EXPECT_LT(root, 120.0);
  EXPECT_GT(foot, -5.0);   // feet at the floor, not a metre below it
  EXPECT_LT(foot, 20.0);
}

TEST(PositionChannels, BandaiChannelsRepeatTheOffsetSoTheyReplaceIt) {
  const Clip clip = LoadClip("dataset-1_bye_normal_001.bvh");
  const int hips = clip.skeleton.FindJoint("Hips");
  ASSERT_GE(hips, 0);
  EXPECT_FALSE(clip.skeleton.joint(hips).position_relative_to_offset);
  const auto [foot, root] = FootAndHipHeight(clip, hips);
  EXPECT_GT(root, 80.0);
  EXPECT_GT(foot, -5.0);
  EXPECT_LT(foot, 20.0);
}

// Bandai's "tired" takes give Hips an OFFSET with z = -452 cm, while its z
// channels stay near 0 and its y channels repeat the OFFSET's y: absolute, so
// the hips are about a metre up (not two) and the feet on the floor.
TEST(PositionChannels, OneLargeOffsetAxisDoesNotDecideAlone) {
  auto clip = ReadBvhFile(KINEMO_TEST_DATA_DIR "/planner_controller/dataset-1_bow_tired_001.bvh");
  ASSERT_TRUE(clip.ok()) << clip.status();
  const int hips = clip->skeleton.FindJoint("Hips");
  ASSERT_GE(hips, 0);
  EXPECT_FALSE(clip->skeleton.joint(hips).position_relative_to_offset);
  const auto [foot, root] = FootAndHipHeight(*clip, hips);
  EXPECT_GT(root, 70.0);
  EXPECT_LT(root, 110.0);
  EXPECT_GT(foot, -5.0);
  EXPECT_LT(foot, 20.0);
}

TEST(PositionChannels, ModeCanBeForced) {
  const std::string path = MotionDataPath("cmu_007_12_first40.bvh");
  BvhReadOptions replace;
  replace.position_channels = PositionChannels::kReplace;
  auto clip = ReadBvhFile(path, replace);
  ASSERT_TRUE(clip.ok()) << clip.status();
  EXPECT_FALSE(clip->skeleton.joint(0).position_relative_to_offset);
  // Forced "replace" puts the hips at the floor: the feet end up far below.
  EXPECT_LT(FootAndHipHeight(*clip, 0).first, -50.0);
}

}  // namespace
}  // namespace kinemo::motion
