// Forward kinematics and Euler helpers on the real files.
#include "common/motion/kinematics.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <vector>

#include "tests/unit/motion/motion_test_util.h"

namespace kinemo::motion {
namespace {

using testing::LoadClip;
using testing::TestFiles;

class FkFileTest : public ::testing::TestWithParam<testing::TestFile> {};

// Every bone keeps its length (the norm of that frame's local translation)
// in every frame, to 1e-6 relative.
TEST_P(FkFileTest, PreservesEveryBoneLengthInEveryFrame) {
  const Clip clip = LoadClip(GetParam().name);
  const Skeleton& sk = clip.skeleton;
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(sk.num_joints()));
  std::vector<Eigen::Matrix3d> rot(static_cast<size_t>(sk.num_joints()));
  double worst = 0.0;
  int checked = 0;
  for (int f = 0; f < clip.num_frames(); ++f) {
    ASSERT_TRUE(ComputeWorldPose(sk, clip.frame(f), pos, rot).ok());
    for (int j = 0; j < sk.num_joints(); ++j) {
      const Joint& joint = sk.joint(j);
      const size_t uj = static_cast<size_t>(j);
      // Orientation stays orthonormal.
      ASSERT_LT((rot[uj] * rot[uj].transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(),
                1e-9);
      if (joint.parent < 0) continue;
      const double expected = LocalTranslation(joint, clip.frame(f)).norm();
      const double actual = (pos[uj] - pos[static_cast<size_t>(joint.parent)]).norm();
      const double rel = std::abs(actual - expected) / std::max(expected, 1e-9);
      if (expected < 1e-9) {
        ASSERT_LT(actual, 1e-9);
        continue;
      }
      worst = std::max(worst, rel);
      ASSERT_LE(rel, 1e-6) << joint.name << " frame " << f;
      ++checked;
    }
  }
  EXPECT_GT(checked, 0);
  RecordProperty("worst_relative_bone_length_error", std::to_string(worst));
}

// The clip-wide helper agrees with the per-frame one.
TEST_P(FkFileTest, WorldPositionsMatrixMatchesPerFrame) {
  const Clip clip = LoadClip(GetParam().name);
  StatusOr<Eigen::MatrixXd> all = ComputeWorldPositions(clip);
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->rows(), clip.num_frames());
  const int f = clip.num_frames() / 2;
  StatusOr<WorldPose> pose = ComputeWorldPose(clip, f);
  ASSERT_TRUE(pose.ok());
  for (int j = 0; j < clip.skeleton.num_joints(); ++j) {
    const Eigen::Vector3d from_all = all->block<1, 3>(f, 3 * j).transpose();
    EXPECT_EQ(from_all, pose->positions[static_cast<size_t>(j)]);
  }
}

// MatrixToEuler inverts EulerToMatrix on every real rotation of the clip and
// returns the file's own angles when they are the nearest solution.
TEST_P(FkFileTest, EulerRoundTripOnRealRotations) {
  const Clip clip = LoadClip(GetParam().name);
  double worst_matrix = 0.0;
  for (int f = 0; f < clip.num_frames(); f += 3) {
    for (const Joint& joint : clip.skeleton.joints()) {
      if (!joint.has_euler_rotation()) continue;
      Eigen::Vector3d e;
      for (int a = 0; a < 3; ++a)
        e[a] = clip.frames(f, joint.rotation_column[static_cast<size_t>(a)]);
      const Eigen::Matrix3d r = EulerToMatrix(joint.rotation_axis, e);
      EXPECT_LT((r - LocalRotation(joint, clip.frame(f))).cwiseAbs().maxCoeff(), 1e-12);
      const Eigen::Vector3d back = MatrixToEuler(r, joint.rotation_axis, e);
      worst_matrix = std::max(worst_matrix,
                              (EulerToMatrix(joint.rotation_axis, back) - r).cwiseAbs().maxCoeff());
      if (std::abs(std::cos(e[1] * M_PI / 180)) > 1e-3) {
        EXPECT_LT((back - e).cwiseAbs().maxCoeff(), 1e-6) << joint.name << " frame " << f;
      }
    }
  }
  EXPECT_LT(worst_matrix, 1e-9);
}

INSTANTIATE_TEST_SUITE_P(RealFiles, FkFileTest, ::testing::ValuesIn(TestFiles()),
                         [](const ::testing::TestParamInfo<testing::TestFile>& info) {
                           std::string n;
                           for (char c : info.param.name)
                             n += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
                           return n;
                         });

// Intrinsic order: for channels "Zrotation Xrotation Yrotation" R = Rz·Rx·Ry.
TEST(KinematicsTest, RotationOrderIsIntrinsicChannelOrder) {
  const Clip clip = LoadClip("dataset-1_bye_normal_001.bvh");
  const Joint& hips = clip.skeleton.joint(1);
  const std::span<const double> f = clip.frame(10);
  const double z = f[static_cast<size_t>(hips.first_channel + 3)];
  const double x = f[static_cast<size_t>(hips.first_channel + 4)];
  const double y = f[static_cast<size_t>(hips.first_channel + 5)];
  const Eigen::Matrix3d expected =
      Eigen::AngleAxisd(z * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
      Eigen::AngleAxisd(x * M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix() *
      Eigen::AngleAxisd(y * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  EXPECT_LT((LocalRotation(hips, f) - expected).cwiseAbs().maxCoeff(), 1e-12);
}

// Bandai: the position channels replace OFFSET; the root's children sit at
// the hips' channel position (≈ 94 cm above the floor).
TEST(KinematicsTest, BandaiPositionChannelsReplaceOffset) {
  const Clip clip = LoadClip("dataset-1_bye_normal_001.bvh");
  StatusOr<WorldPose> pose = ComputeWorldPose(clip, 0);
  ASSERT_TRUE(pose.ok());
  const int hips = clip.skeleton.FindJoint("Hips");
  const Eigen::Vector3d local = LocalTranslation(clip.skeleton.joint(hips), clip.frame(0));
  EXPECT_NEAR(local.y(), clip.frames(0, clip.channel_offset(hips) + 1), 0);
  EXPECT_GT(pose->positions[static_cast<size_t>(hips)].y(), 80.0);
  EXPECT_LT(pose->positions[static_cast<size_t>(hips)].y(), 110.0);
}

TEST(KinematicsTest, SizeMismatchIsAnError) {
  const Clip clip = LoadClip("131_01.bvh");
  std::vector<Eigen::Vector3d> pos(5);
  std::vector<Eigen::Matrix3d> rot(5);
  EXPECT_FALSE(ComputeWorldPose(clip.skeleton, clip.frame(0), pos, rot).ok());
  EXPECT_FALSE(ComputeWorldPose(clip, clip.num_frames()).ok());
  EXPECT_FALSE(ComputeWorldPose(clip, -1).ok());
}

TEST(KinematicsTest, EulerGimbalLockStillReproducesRotation) {
  for (const std::array<int, 3> axes :
       {std::array<int, 3>{2, 0, 1}, std::array<int, 3>{2, 1, 0}, std::array<int, 3>{0, 1, 2}}) {
    const Eigen::Vector3d e(30.0, 90.0, -20.0);
    const Eigen::Matrix3d r = EulerToMatrix(axes, e);
    const Eigen::Vector3d back = MatrixToEuler(r, axes, Eigen::Vector3d(25.0, 85.0, 0.0));
    EXPECT_LT((EulerToMatrix(axes, back) - r).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_NEAR(back[0], 25.0, 1e-9);  // first angle taken from the reference
  }
}

TEST(KinematicsTest, EulerUnwrapsTowardsReference) {
  const std::array<int, 3> axes = {2, 1, 0};
  const Eigen::Vector3d e(179.0, 10.0, -170.0);
  const Eigen::Matrix3d r = EulerToMatrix(axes, e);
  const Eigen::Vector3d near_ref =
      MatrixToEuler(r, axes, Eigen::Vector3d(-178.0 + 360.0, 12.0, 190.0 - 360.0 + 360.0));
  EXPECT_NEAR(near_ref[0], 179.0, 1e-9);
  EXPECT_NEAR(near_ref[2], 190.0, 1e-9);
  const Eigen::Vector3d shifted =
      MatrixToEuler(r, axes, Eigen::Vector3d(179.0 + 720.0, 10.0, -170.0));
  EXPECT_NEAR(shifted[0], 179.0 + 720.0, 1e-9);
}

}  // namespace
}  // namespace kinemo::motion
