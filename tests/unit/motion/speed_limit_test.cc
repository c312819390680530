// The upper body's speed ceiling (common/motion/speed_limit.h) on real motion
// capture: a BEAT2 take played 1.3 times as fast.
#include "common/motion/speed_limit.h"

#include <gtest/gtest.h>

#include <string>

#include "common/motion/body_regions.h"
#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/motion/resample.h"

namespace kinemo::motion {
namespace {

constexpr double kSpeedMpu = 0.01;  // BEAT2's SMPL-X files are in centimetres

Clip SpeedTake() {
  StatusOr<Clip> c = ReadBvhFile(std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2/2_scott_0_2_2.bvh");
  EXPECT_TRUE(c.ok()) << c.status();
  return c.ok() ? *std::move(c) : Clip{};
}

// 20 s of the take played 1.3 times as fast (resampled to 30 / 1.3 fps and
// shown at 30 fps).
Clip SpeedFaster(const Clip& take) {
  Clip part;
  part.skeleton = take.skeleton;
  part.frame_time_s = take.frame_time_s;
  part.frames = take.frames.topRows(std::min(take.num_frames(), 600));
  Clip out = Resample(part, 1 / (1.3 * take.frame_time_s)).value();
  out.frame_time_s = take.frame_time_s;
  return out;
}

TEST(SpeedLimit, AFasterMotionComesUnderTheTakesOwnFastest) {
  const Clip take = SpeedTake();
  ASSERT_GT(take.num_frames(), 600);
  auto joints = FindUpperBodyJoints(take.skeleton, MapBodyRegions(take.skeleton));
  ASSERT_TRUE(joints.ok()) << joints.status();
  EXPECT_EQ(joints->measured.size(), 5u);  // head, wrists, elbows
  const double fastest = MaxUpperBodySpeed(take, *joints, kSpeedMpu);
  EXPECT_GT(fastest, 1.0);  // the speaker's hands reach 1.8 m/s
  EXPECT_LT(fastest, 3.0);
  Clip fast = SpeedFaster(take);
  const Clip before = fast;
  SpeedLimitParams p;
  p.max_speed_m_s = fastest;
  p.meters_per_unit = kSpeedMpu;
  auto r = LimitUpperBodySpeed(&fast, *joints, p);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_GT(r->max_before_m_s, 1.2 * fastest);
  EXPECT_GT(r->frames_over_before, 0);
  EXPECT_LE(r->max_after_m_s, fastest * 1.001);
  EXPECT_NEAR(MaxUpperBodySpeed(fast, *joints, kSpeedMpu), r->max_after_m_s, 1e-9);
  EXPECT_GT(r->frames_changed, 0);
  // Only the smoothed joints' rotation channels changed: the root and legs
  // (and the fingers) are as they were.
  std::vector<bool> may(static_cast<size_t>(fast.skeleton.num_channels()), false);
  for (int j : joints->smoothed) {
    for (int c : fast.skeleton.joint(j).rotation_column) may[static_cast<size_t>(c)] = true;
  }
  for (int c = 0; c < fast.skeleton.num_channels(); ++c) {
    if (!may[static_cast<size_t>(c)]) {
      ASSERT_EQ((fast.frames.col(c) - before.frames.col(c)).cwiseAbs().maxCoeff(), 0.0) << c;
    }
  }
  // Smoothing, not replacing: the wrists stay within a few centimetres of
  // the input on average.
  auto pa = ComputeWorldPositions(before), pb = ComputeWorldPositions(fast);
  ASSERT_TRUE(pa.ok() && pb.ok());
  const KeyJoints key = FindKeyJoints(take.skeleton, MapBodyRegions(take.skeleton)).value();
  double moved = 0;
  for (int f = 0; f < fast.num_frames(); ++f) {
    moved += ((*pa).row(f).segment<3>(3 * key.right_hand) - (*pb).row(f).segment<3>(3 * key.right_hand)).norm();
  }
  EXPECT_LT(moved / fast.num_frames() * kSpeedMpu, 0.03);

  // The take itself is under its own ceiling: nothing changes.
  Clip same = take;
  auto none = LimitUpperBodySpeed(&same, *joints, p);
  ASSERT_TRUE(none.ok());
  EXPECT_EQ(none->frames_changed, 0);
  EXPECT_EQ(none->passes, 0);
  EXPECT_TRUE(same.frames == take.frames);
}

TEST(SpeedLimit, ACancelledCallStopsBeforeItsFirstPass) {
  const Clip take = SpeedTake();
  auto joints = FindUpperBodyJoints(take.skeleton, MapBodyRegions(take.skeleton)).value();
  Clip fast = SpeedFaster(take);
  const Clip before = fast;
  CancelToken cancel;
  cancel.Cancel();
  SpeedLimitParams p;
  p.max_speed_m_s = MaxUpperBodySpeed(take, joints, kSpeedMpu);
  p.meters_per_unit = kSpeedMpu;
  p.cancel = &cancel;
  auto r = LimitUpperBodySpeed(&fast, joints, p);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsCancelled(r.status())) << r.status();
  EXPECT_TRUE(fast.frames == before.frames);
}

TEST(SpeedLimit, BadParamsNameTheirField) {
  Clip c = SpeedTake();
  auto joints = FindUpperBodyJoints(c.skeleton, MapBodyRegions(c.skeleton)).value();
  for (auto [field, set] : std::initializer_list<std::pair<const char*, void (*)(SpeedLimitParams&)>>{
           {"max_speed_m_s", [](SpeedLimitParams& p) { p.max_speed_m_s = 0; }},
           {"meters_per_unit", [](SpeedLimitParams& p) { p.meters_per_unit = -1; }},
           {"reach_s", [](SpeedLimitParams& p) { p.reach_s = 5; }},
           {"max_passes", [](SpeedLimitParams& p) { p.max_passes = -1; }}}) {
    SpeedLimitParams p;
    p.max_speed_m_s = 2;
    set(p);
    const Clip before = c;
    auto r = LimitUpperBodySpeed(&c, joints, p);
    ASSERT_FALSE(r.ok()) << field;
    EXPECT_TRUE(absl::IsInvalidArgument(r.status())) << field;
    EXPECT_NE(std::string(r.status().message()).find(field), std::string::npos) << r.status();
    EXPECT_TRUE(c.frames == before.frames);
  }
}

}  // namespace
}  // namespace kinemo::motion
