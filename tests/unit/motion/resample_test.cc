// Resampling real clips between frame rates.
#include "common/motion/resample.h"

#include <gtest/gtest.h>

#include <cmath>

#include "common/motion/kinematics.h"
#include "tests/unit/motion/motion_test_util.h"

namespace kinemo::motion {
namespace {

using testing::LoadClip;

// Largest angle (degrees) between the local rotations of all Euler joints
// in frame fa of a and frame fb of b, plus largest position-channel gap.
struct Gap {
  double rotation_deg = 0.0;
  double position = 0.0;
};
Gap FrameGap(const Clip& a, int fa, const Clip& b, int fb) {
  Gap g;
  for (const Joint& joint : a.skeleton.joints()) {
    const Eigen::Matrix3d ra = LocalRotation(joint, a.frame(fa));
    const Eigen::Matrix3d rb = LocalRotation(joint, b.frame(fb));
    const double angle = Eigen::AngleAxisd(ra.transpose() * rb).angle() * 180.0 / M_PI;
    g.rotation_deg = std::max(g.rotation_deg, angle);
    for (int axis = 0; axis < 3; ++axis) {
      const int col = joint.position_column[static_cast<size_t>(axis)];
      if (col >= 0)
        g.position = std::max(g.position, std::abs(a.frames(fa, col) - b.frames(fb, col)));
    }
  }
  return g;
}

// Largest jump of any rotation channel between consecutive frames.
double MaxAngleStep(const Clip& c) {
  double worst = 0.0;
  for (const Joint& joint : c.skeleton.joints()) {
    for (int k = 0; k < joint.num_rotations; ++k) {
      const int col = joint.rotation_column[static_cast<size_t>(k)];
      for (int f = 1; f < c.num_frames(); ++f) {
        worst = std::max(worst, std::abs(c.frames(f, col) - c.frames(f - 1, col)));
      }
    }
  }
  return worst;
}

TEST(ResampleTest, Bandai30To60To30ReturnsTheOriginal) {
  const Clip clip = LoadClip("dataset-1_bye_normal_001.bvh");
  StatusOr<Clip> up = Resample(clip, 60.0);
  ASSERT_TRUE(up.ok()) << up.status();
  EXPECT_EQ(up->num_frames(), 2 * clip.num_frames() - 1);
  EXPECT_NEAR(up->frame_time_s, 1.0 / 60, 1e-15);
  // Duration preserved within one frame.
  EXPECT_NEAR(up->duration_s(), clip.duration_s(), clip.frame_time_s);
  StatusOr<Clip> down = Resample(*up, 30.0);
  ASSERT_TRUE(down.ok()) << down.status();
  ASSERT_EQ(down->num_frames(), clip.num_frames());
  double worst_rot = 0.0, worst_pos = 0.0, worst_channel = 0.0;
  for (int f = 0; f < clip.num_frames(); ++f) {
    const Gap g = FrameGap(clip, f, *down, f);
    worst_rot = std::max(worst_rot, g.rotation_deg);
    worst_pos = std::max(worst_pos, g.position);
  }
  // The source's frame time is 0.0333333 s, not exactly 1/30: frames drift by
  // at most 111 · 3.3e-8 s, hence the small tolerances.
  EXPECT_LT(worst_rot, 0.05);
  EXPECT_LT(worst_pos, 0.05);
  // And the Euler channels themselves come back, modulo 360° (the output is
  // unwrapped to be continuous where the source jumps between ±180°).
  for (int f = 0; f < clip.num_frames(); ++f) {
    for (int c = 0; c < clip.frames.cols(); ++c) {
      worst_channel = std::max(
          worst_channel, std::abs(std::remainder(clip.frames(f, c) - down->frames(f, c), 360.0)));
    }
  }
  EXPECT_LT(worst_channel, 0.1);
}

// Midpoints of 30 → 60 lie between their neighbours (slerp), and the
// upsampled curves are continuous (no 360° jumps).
TEST(ResampleTest, UpsampledFramesInterpolateNeighbours) {
  const Clip clip = LoadClip("dataset-1_bye_normal_001.bvh");
  StatusOr<Clip> up = Resample(clip, 2.0 / clip.frame_time_s);  // exactly twice the rate
  ASSERT_TRUE(up.ok());
  ASSERT_EQ(up->num_frames(), 2 * clip.num_frames() - 1);
  for (int f = 0; f + 1 < clip.num_frames(); ++f) {
    // Even frames equal the source.
    const Gap same = FrameGap(clip, f, *up, 2 * f);
    EXPECT_LT(same.rotation_deg, 1e-6);
    EXPECT_LT(same.position, 1e-9);
    // The midpoint is equally far (in angle) from both neighbours.
    for (const Joint& joint : clip.skeleton.joints()) {
      const Eigen::Matrix3d r0 = LocalRotation(joint, clip.frame(f));
      const Eigen::Matrix3d r1 = LocalRotation(joint, clip.frame(f + 1));
      const Eigen::Matrix3d rm = LocalRotation(joint, up->frame(2 * f + 1));
      const double a0 = Eigen::AngleAxisd(r0.transpose() * rm).angle();
      const double a1 = Eigen::AngleAxisd(rm.transpose() * r1).angle();
      const double a01 = Eigen::AngleAxisd(r0.transpose() * r1).angle();
      EXPECT_NEAR(a0, a1, 1e-7) << joint.name;
      EXPECT_NEAR(a0 + a1, a01, 1e-7) << joint.name;
    }
  }
  EXPECT_LE(MaxAngleStep(*up), MaxAngleStep(clip) + 1e-6);
}

// 120 → 30 fps on the 31-joint CMU clip: every 4th frame (approximately, the
// source rate is 1/0.0083333 ≈ 120.0005 fps), same duration.
TEST(ResampleTest, Cmu31From120To30) {
  const Clip clip = LoadClip("131_01.bvh");
  StatusOr<Clip> down = Resample(clip, 30.0);
  ASSERT_TRUE(down.ok()) << down.status();
  EXPECT_EQ(down->num_frames(), 249);
  EXPECT_NEAR(down->fps(), 30.0, 1e-12);
  EXPECT_NEAR(down->duration_s(), clip.duration_s(), clip.frame_time_s + down->frame_time_s);
  double worst_rot = 0.0;
  for (int k = 0; k < down->num_frames(); ++k) {
    const Gap g = FrameGap(clip, std::min(4 * k, clip.num_frames() - 1), *down, k);
    worst_rot = std::max(worst_rot, g.rotation_deg);
  }
  EXPECT_LT(worst_rot, 1.0);  // drift of < 0.1 source frame
  // Channels stay continuous despite the Euler re-extraction.
  EXPECT_LT(MaxAngleStep(*down), 4 * MaxAngleStep(clip) + 1e-6);
  // Bones keep their lengths after resampling.
  StatusOr<WorldPose> pose = ComputeWorldPose(*down, 100);
  ASSERT_TRUE(pose.ok());
  for (const Joint& joint : down->skeleton.joints()) {
    if (joint.parent < 0) continue;
    const size_t j = static_cast<size_t>(down->skeleton.FindJoint(joint.name));
    EXPECT_NEAR((pose->positions[j] - pose->positions[static_cast<size_t>(joint.parent)]).norm(),
                joint.offset.norm(), 1e-9);
  }
}

TEST(ResampleTest, Cmu60To24KeepsSpan) {
  const Clip clip = LoadClip("cmu_002_03.bvh");
  StatusOr<Clip> c = Resample(clip, 24.0);
  ASSERT_TRUE(c.ok());
  const double span = (clip.num_frames() - 1) * clip.frame_time_s;
  EXPECT_EQ(c->num_frames(), static_cast<int>(std::floor(span * 24.0 + 0.01)) + 1);
  const Gap first = FrameGap(clip, 0, *c, 0);
  EXPECT_LT(first.rotation_deg, 1e-6);
}

TEST(ResampleTest, RejectsBadRates) {
  const Clip clip = LoadClip("cmu_007_12_first40.bvh");
  EXPECT_FALSE(Resample(clip, 0.0).ok());
  EXPECT_FALSE(Resample(clip, -30.0).ok());
  EXPECT_FALSE(Resample(clip, std::nan("")).ok());
  EXPECT_FALSE(Resample(clip, 1e9).ok());
}

}  // namespace
}  // namespace kinemo::motion
