// Body-region maps and key joints on the four real skeletons.
#include "common/motion/body_regions.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <string>

#include "common/motion/kinematics.h"
#include "tests/unit/motion/motion_test_util.h"

namespace kinemo::motion {
namespace {

using testing::LoadClip;

struct RegionCase {
  std::string file;
  SkeletonFamily family;
  std::map<BodyRegion, int> counts;
  std::string head, left_hand, right_hand, left_foot, right_foot, left_toe, right_toe;
};

std::vector<RegionCase> Cases() {
  using R = BodyRegion;
  return {
      {"dataset-1_bye_normal_001.bvh",
       SkeletonFamily::kBandai22,
       {{R::kTrunk, 4},
        {R::kHead, 2},
        {R::kLeftArm, 3},
        {R::kRightArm, 3},
        {R::kLeftHand, 1},
        {R::kRightHand, 1},
        {R::kLeftLeg, 4},
        {R::kRightLeg, 4}},
       "Head",
       "Hand_L",
       "Hand_R",
       "Foot_L",
       "Foot_R",
       "Toes_L",
       "Toes_R"},
      {"cmu_002_03.bvh",
       SkeletonFamily::kCmuIclone100,
       {{R::kTrunk, 10},
        {R::kHead, 13},
        {R::kLeftArm, 8},
        {R::kRightArm, 8},
        {R::kLeftHand, 16},
        {R::kRightHand, 16},
        {R::kLeftLeg, 15},
        {R::kRightLeg, 15}},
       "CC_Base_Head",
       "CC_Base_L_Hand",
       "CC_Base_R_Hand",
       "CC_Base_L_Foot",
       "CC_Base_R_Foot",
       "CC_Base_L_ToeBaseShareBone",
       "CC_Base_R_ToeBase"},
      {"cmu_007_12_first40.bvh",
       SkeletonFamily::kCmuIclone100,
       {{R::kTrunk, 9},
        {R::kHead, 13},
        {R::kLeftArm, 8},
        {R::kRightArm, 8},
        {R::kLeftHand, 16},
        {R::kRightHand, 16},
        {R::kLeftLeg, 15},
        {R::kRightLeg, 15}},
       "CC_Base_Head",
       "CC_Base_L_Hand",
       "CC_Base_R_Hand",
       "CC_Base_L_Foot",
       "CC_Base_R_Foot",
       "CC_Base_L_ToeBaseShareBone",
       "CC_Base_R_ToeBase"},
      {"131_01.bvh",
       SkeletonFamily::kCmu31,
       {{R::kTrunk, 4},
        {R::kHead, 3},
        {R::kLeftArm, 3},
        {R::kRightArm, 3},
        {R::kLeftHand, 4},
        {R::kRightHand, 4},
        {R::kLeftLeg, 5},
        {R::kRightLeg, 5}},
       "Head",
       "LeftWrist",
       "RightWrist",
       "LeftAnkle",
       "RightAnkle",
       "LeftToe",
       "RightToe"},
      {"../paired/beat2/2_scott_0_2_2.bvh",
       SkeletonFamily::kSmplx55,
       {{R::kTrunk, 4},
        {R::kHead, 5},
        {R::kLeftArm, 3},
        {R::kRightArm, 3},
        {R::kLeftHand, 16},
        {R::kRightHand, 16},
        {R::kLeftLeg, 4},
        {R::kRightLeg, 4}},
       "head",
       "left_wrist",
       "right_wrist",
       "left_ankle",
       "right_ankle",
       "left_foot",
       "right_foot"},
  };
}

class BodyRegionFileTest : public ::testing::TestWithParam<RegionCase> {};

TEST_P(BodyRegionFileTest, EveryJointMappedByARule) {
  const RegionCase& rc = GetParam();
  const Clip clip = LoadClip(rc.file);
  EXPECT_EQ(DetectSkeletonFamily(clip.skeleton), rc.family);
  const BodyRegionMap map = MapBodyRegions(clip.skeleton);
  EXPECT_EQ(map.family, rc.family);
  ASSERT_EQ(map.region.size(), static_cast<size_t>(clip.skeleton.num_joints()));
  for (int j = 0; j < clip.skeleton.num_joints(); ++j) {
    EXPECT_TRUE(map.from_rule[static_cast<size_t>(j)])
        << clip.skeleton.joint(j).name << " has no rule in " << SkeletonFamilyName(rc.family);
  }
  int total = 0;
  for (const auto& [region, count] : rc.counts) {
    EXPECT_EQ(static_cast<int>(map.JointsIn(region).size()), count) << BodyRegionName(region);
    total += count;
  }
  EXPECT_EQ(total, clip.skeleton.num_joints());
  // Name sanity: left/right never swapped, nothing of a hand outside a hand.
  for (int j = 0; j < clip.skeleton.num_joints(); ++j) {
    const std::string& name = clip.skeleton.joint(j).name;
    const BodyRegion r = map.region[static_cast<size_t>(j)];
    if (r == BodyRegion::kLeftArm || r == BodyRegion::kLeftHand || r == BodyRegion::kLeftLeg) {
      EXPECT_TRUE(name.find("_L") != std::string::npos || name.find("Left") != std::string::npos ||
                  name[0] == 'L' || name[0] == 'l')
          << name;
    }
  }
}

// The region map is consistent with the skeleton's geometry: in the first
// frame the left hand is on the opposite side of the body from the right hand
// and the head is above the feet.
TEST_P(BodyRegionFileTest, KeyJointsFoundAndPlausible) {
  const RegionCase& rc = GetParam();
  const Clip clip = LoadClip(rc.file);
  const BodyRegionMap map = MapBodyRegions(clip.skeleton);
  StatusOr<KeyJoints> k = FindKeyJoints(clip.skeleton, map);
  ASSERT_TRUE(k.ok()) << k.status();
  const auto name = [&](int j) { return j < 0 ? std::string("-") : clip.skeleton.joint(j).name; };
  EXPECT_EQ(name(k->head), rc.head);
  EXPECT_EQ(name(k->left_hand), rc.left_hand);
  EXPECT_EQ(name(k->right_hand), rc.right_hand);
  EXPECT_EQ(name(k->left_foot), rc.left_foot);
  EXPECT_EQ(name(k->right_foot), rc.right_foot);
  EXPECT_EQ(name(k->left_toe), rc.left_toe);
  EXPECT_EQ(name(k->right_toe), rc.right_toe);
  StatusOr<WorldPose> pose = ComputeWorldPose(clip, 0);
  ASSERT_TRUE(pose.ok());
  const auto p = [&](int j) { return pose->positions[static_cast<size_t>(j)]; };
  const Eigen::Vector3d feet_mid = 0.5 * (p(k->left_foot) + p(k->right_foot));
  const Eigen::Vector3d up = (p(k->head) - feet_mid).normalized();
  EXPECT_GT((p(k->head) - feet_mid).norm(),
            50.0 * (rc.family == SkeletonFamily::kCmu31 ? 0.1 : 1.0));
  // Hands lie apart from each other across the body.
  EXPECT_GT((p(k->left_hand) - p(k->right_hand)).norm(), 0.0);
  // Toes below the head.
  EXPECT_GT(up.dot(p(k->head) - p(k->left_toe)), 0.0);
}

// The generic name heuristics (for unknown skeletons) agree with the
// hand-written maps on all three skeletons.
TEST_P(BodyRegionFileTest, HeuristicsAgreeWithBuiltInMaps) {
  const Clip clip = LoadClip(GetParam().file);
  const BodyRegionMap builtin = MapBodyRegions(clip.skeleton);
  const BodyRegionMap guessed = MapBodyRegions(clip.skeleton, GenericBodyRegionRules());
  for (int j = 0; j < clip.skeleton.num_joints(); ++j) {
    EXPECT_EQ(BodyRegionName(guessed.region[static_cast<size_t>(j)]),
              BodyRegionName(builtin.region[static_cast<size_t>(j)]))
        << clip.skeleton.joint(j).name;
  }
}

INSTANTIATE_TEST_SUITE_P(RealFiles, BodyRegionFileTest, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<RegionCase>& info) {
                           std::string n;
                           for (char c : info.param.file)
                             n += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
                           return n;
                         });

TEST(BodyRegionRulesTest, ParsesRuleText) {
  StatusOr<BodyRegionRules> rules = BodyRegionRules::Parse(
      "# comment\n\n  *Hand*  left_hand  # trailing\nLeft Up Leg left_leg\nHips trunk\n",
      "rules.txt");
  ASSERT_TRUE(rules.ok()) << rules.status();
  EXPECT_EQ(rules->rules().size(), 3u);
  EXPECT_EQ(rules->Match("MyHand_01"), BodyRegion::kLeftHand);
  EXPECT_EQ(rules->Match("left up leg"), BodyRegion::kLeftLeg);  // case-insensitive, spaces
  EXPECT_EQ(rules->Match("Spine"), std::nullopt);
}

TEST(BodyRegionRulesTest, ParseErrorsNameTheLine) {
  StatusOr<BodyRegionRules> bad = BodyRegionRules::Parse("Hips trunk\nHead  noggin\n", "r.txt");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(std::string(bad.status().message()),
              ::testing::StartsWith("r.txt:2: unknown region 'noggin'"));
  bad = BodyRegionRules::Parse("Hips\n", "r.txt");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(std::string(bad.status().message()), ::testing::StartsWith("r.txt:1:"));
  EXPECT_EQ(BodyRegionRules::LoadFile("/nonexistent/rules.txt").status().code(),
            absl::StatusCode::kNotFound);
}

// Rules for another skeleton: a map of a few names; everything else inherits
// from its parent (fingers follow the hand).
TEST(BodyRegionRulesTest, MapWithInheritance) {
  const Clip clip = LoadClip("131_01.bvh");
  const BodyRegionRules rules = BodyRegionRules::FromMap({{"Hips", BodyRegion::kTrunk},
                                                          {"LeftWrist", BodyRegion::kLeftHand},
                                                          {"LeftCollar", BodyRegion::kLeftArm},
                                                          {"Neck", BodyRegion::kHead}});
  const BodyRegionMap map = MapBodyRegions(clip.skeleton, rules);
  EXPECT_EQ(map.num_from_rule(), 4);
  const auto region = [&](const char* n) {
    return map.region[static_cast<size_t>(clip.skeleton.FindJoint(n))];
  };
  EXPECT_EQ(region("LFingers"), BodyRegion::kLeftHand);
  EXPECT_EQ(region("LThumb"), BodyRegion::kLeftHand);
  EXPECT_EQ(region("LeftElbow"), BodyRegion::kLeftArm);
  EXPECT_EQ(region("Head"), BodyRegion::kHead);
  EXPECT_EQ(region("RightWrist"), BodyRegion::kTrunk);  // no rule: inherits trunk
}

TEST(BodyRegionRulesTest, LoadsRuleFile) {
  const std::string path = testing::TempPath("rules.txt");
  {
    std::ofstream f(path);
    f << "Hips trunk\nLeft* left_leg\nRight* right_leg\n";
  }
  StatusOr<BodyRegionRules> rules = BodyRegionRules::LoadFile(path);
  ASSERT_TRUE(rules.ok()) << rules.status();
  EXPECT_EQ(rules->Match("LeftKnee"), BodyRegion::kLeftLeg);
}

TEST(BodyRegionRulesTest, GlobMatch) {
  EXPECT_TRUE(GlobMatch("CC_Base_?_Eye", "CC_Base_L_Eye"));
  EXPECT_FALSE(GlobMatch("CC_Base_L_Mid?", "CC_Base_L_MidToe1"));
  EXPECT_TRUE(GlobMatch("CC_Base_L_*Toe1", "CC_Base_L_MidToe1"));
  EXPECT_TRUE(GlobMatch("*", ""));
  EXPECT_TRUE(GlobMatch("a*b*c", "aXXbYYc"));
  EXPECT_FALSE(GlobMatch("a*b*c", "aXXbYY"));
  EXPECT_TRUE(GlobMatch("lhand", "LHand"));
}

TEST(BodyRegionTest, NamesRoundTrip) {
  for (int i = 0; i < kNumBodyRegions; ++i) {
    const BodyRegion r = static_cast<BodyRegion>(i);
    EXPECT_EQ(ParseBodyRegion(BodyRegionName(r)), r);
  }
  EXPECT_EQ(ParseBodyRegion("elbow"), std::nullopt);
}

TEST(BodyRegionTest, UnknownSkeletonFailsKeyJointsClearly) {
  const Clip clip = LoadClip("131_01.bvh");
  const BodyRegionMap map = MapBodyRegions(clip.skeleton, BodyRegionRules());  // all trunk
  StatusOr<KeyJoints> k = FindKeyJoints(clip.skeleton, map);
  ASSERT_FALSE(k.ok());
  EXPECT_THAT(std::string(k.status().message()),
              ::testing::HasSubstr("no head, left hand, right hand"));
}

}  // namespace
}  // namespace kinemo::motion
