// Motion compare (common/evaluation) on real motion capture: the BEAT2 takes
// of tests/data/paired/beat2 (SMPL-X, 55 joints, centimetres) and Bandai
// clips (22 joints).
#include "common/evaluation/motion_compare.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "common/motion/bvh.h"
#include "common/motion/resample.h"
#include "services/planner/library/library.h"

namespace kinemo::evaluation {
namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;
const std::string kTake1 = kData + "/paired/beat2/2_scott_0_1_1.bvh";
const std::string kTake2 = kData + "/paired/beat2/2_scott_0_2_2.bvh";
const std::string kBandai = kData + "/planner_gesture/dataset-1_guide_normal_001.bvh";

motion::Clip Read(const std::string& path) {
  auto c = motion::ReadBvhFile(path);
  EXPECT_TRUE(c.ok()) << c.status();
  return c.ok() ? *std::move(c) : motion::Clip{};
}

double Scale(const motion::Clip& c) { return SnapMetersPerUnit(planner::EstimateMetersPerUnit(c.skeleton)); }

RoleTrack Track(const motion::Clip& c) {
  auto t = ExtractRoleTrack(c, Scale(c));
  EXPECT_TRUE(t.ok()) << t.status();
  return t.ok() ? *std::move(t) : RoleTrack{};
}

// Frames [first, first + n) of a clip.
motion::Clip Cut(const motion::Clip& c, int first, int n) {
  motion::Clip out = c;
  out.frames = c.frames.middleRows(first, n);
  return out;
}

// The clip in other units: offsets, end sites and position channels × k.
motion::Clip Rescale(const motion::Clip& c, double k) {
  std::vector<motion::Joint> joints(c.skeleton.joints().begin(), c.skeleton.joints().end());
  for (auto& j : joints) {
    j.offset *= k;
    if (j.end_site) *j.end_site *= k;
  }
  motion::Clip out = c;
  out.skeleton = *motion::Skeleton::Create(joints);
  for (const auto& j : c.skeleton.joints()) {
    for (int a = 0; a < 3; ++a) {
      if (j.position_column[static_cast<size_t>(a)] >= 0) out.frames.col(j.position_column[static_cast<size_t>(a)]) *= k;
    }
  }
  return out;
}

class Beat2 : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    take1_ = new motion::Clip(Read(kTake1));
    take2_ = new motion::Clip(Read(kTake2));
  }
  static void TearDownTestSuite() {
    delete take1_;
    delete take2_;
  }
  static motion::Clip* take1_;
  static motion::Clip* take2_;
};
motion::Clip* Beat2::take1_ = nullptr;
motion::Clip* Beat2::take2_ = nullptr;

TEST(SnapMetersPerUnit, SnapsNearStandardUnits) {
  EXPECT_DOUBLE_EQ(SnapMetersPerUnit(0.0104), 0.01);
  EXPECT_DOUBLE_EQ(SnapMetersPerUnit(0.9), 1.0);
  EXPECT_DOUBLE_EQ(SnapMetersPerUnit(0.026), 0.0254);
  EXPECT_DOUBLE_EQ(SnapMetersPerUnit(0.05), 0.05);  // no unit near: kept
}

TEST_F(Beat2, RolesAndScaleOfBothSkeletons) {
  // The BEAT2 BVH is in centimetres; the Bandai clips too.
  EXPECT_DOUBLE_EQ(Scale(*take1_), 0.01);
  const motion::Clip bandai = Read(kBandai);
  EXPECT_DOUBLE_EQ(Scale(bandai), 0.01);
  for (const motion::Clip* c : {static_cast<const motion::Clip*>(take1_), &bandai}) {
    const RoleTrack t = Track(*c);
    ASSERT_EQ(t.num_frames(), c->num_frames());
    // Standing people: head 1.4-1.9 m above the feet, wrists below the head,
    // elbows between shoulders and wrists (arm lengths 0.2-0.4 m).
    const double head = (t.At(0, kHead) - t.At(0, kLeftFoot)).y();
    EXPECT_GT(head, 1.2);
    EXPECT_LT(head, 1.9);
    for (int side = 0; side < 2; ++side) {
      const double upper = (t.At(0, kLeftElbow + side) - t.At(0, kLeftShoulder + side)).norm();
      const double fore = (t.At(0, kLeftWrist + side) - t.At(0, kLeftElbow + side)).norm();
      EXPECT_GT(upper, 0.15);
      EXPECT_LT(upper, 0.4);
      EXPECT_GT(fore, 0.15);
      EXPECT_LT(fore, 0.4);
    }
  }
}

TEST_F(Beat2, ATakeAgainstItselfScoresZero) {
  const RoleTrack t = Track(*take1_);
  const std::vector<RoleTrack> refs = {t};
  auto c = Compare(t, refs, nullptr, {});
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_NEAR(c->hellinger_speed, 0, 1e-6);
  EXPECT_NEAR(c->hellinger_accel, 0, 1e-6);
  EXPECT_NEAR(c->fd_kinetic, 0, 1e-6);
  EXPECT_DOUBLE_EQ(c->generated.jerk_mean_m_s3, c->reference.jerk_mean_m_s3);
  // The README's figures of this speaker: wrist speed mean 0.35-0.57 m/s.
  EXPECT_GT(c->generated.hand_speed_mean_m_s, 0.3);
  EXPECT_LT(c->generated.hand_speed_mean_m_s, 0.6);
  EXPECT_GT(c->generated.hands_moving_fraction, 0.3);
  EXPECT_GT(c->windows, 100);
}

TEST_F(Beat2, OtherTakeIsCloseAndAStillPoseIsFar) {
  const RoleTrack t1 = Track(*take1_), t2 = Track(*take2_);
  const std::vector<RoleTrack> refs = {t2};
  auto natural = Compare(t1, refs, nullptr, {});
  ASSERT_TRUE(natural.ok()) << natural.status();
  motion::Clip still = *take1_;
  for (int f = 0; f < still.num_frames(); ++f) still.frames.row(f) = take1_->frames.row(0);
  auto dead = Compare(Track(still), refs, nullptr, {});
  ASSERT_TRUE(dead.ok()) << dead.status();
  // The same speaker's other take: close; a still pose: as far as it gets.
  EXPECT_LT(natural->hellinger_speed, 0.3);
  EXPECT_LT(natural->hellinger_accel, 0.3);
  EXPECT_GT(dead->hellinger_speed, 0.8);
  EXPECT_GT(dead->hellinger_accel, 0.8);
  EXPECT_GT(dead->fd_kinetic, 3 * natural->fd_kinetic);
  EXPECT_EQ(dead->generated.hands_moving_fraction, 0);
  EXPECT_EQ(dead->generated.kinematic_beats, 0);
  EXPECT_NEAR(dead->generated.jerk_mean_m_s3, 0, 1e-9);
}

TEST_F(Beat2, UnitsAndFrameRateDoNotChangeTheMetres) {
  const RoleTrack t2 = Track(*take2_);
  const std::vector<RoleTrack> refs = {t2};
  const motion::Clip metres = Rescale(*take1_, 0.01);
  EXPECT_DOUBLE_EQ(Scale(metres), 1.0);
  auto a = Compare(Track(*take1_), refs, nullptr, {});
  auto b = Compare(Track(metres), refs, nullptr, {});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NEAR(a->hellinger_speed, b->hellinger_speed, 1e-9);
  EXPECT_NEAR(a->fd_kinetic, b->fd_kinetic, 1e-6);
  EXPECT_NEAR(a->generated.jerk_mean_m_s3, b->generated.jerk_mean_m_s3, 1e-6);
  EXPECT_NEAR(a->generated.hands_raised_fraction, b->generated.hands_raised_fraction, 1e-12);
  // At 60 fps the clip is resampled back to 30 fps: nearly the same motion.
  auto fast = motion::Resample(*take1_, 60);
  ASSERT_TRUE(fast.ok());
  const RoleTrack t60 = Track(*fast);
  EXPECT_NEAR(t60.frame_time_s, 1.0 / 30, 1e-9);
  auto c = Compare(t60, refs, nullptr, {});
  ASSERT_TRUE(c.ok());
  EXPECT_NEAR(c->hellinger_speed, a->hellinger_speed, 0.03);
  EXPECT_NEAR(c->generated.hand_speed_mean_m_s, a->generated.hand_speed_mean_m_s, 0.02);
}

TEST_F(Beat2, LongestCopyFindsACutOfTheLibrary) {
  const std::vector<RoleTrack> lib = {Track(*take1_)};
  // Frames 300..599 of take 1 followed by 200 frames of take 2: 300 copied.
  motion::Clip mixed = Cut(*take1_, 300, 500);
  mixed.frames.bottomRows(200) = take2_->frames.middleRows(100, 200);
  const RoleTrack m = Track(mixed);
  std::vector<int> runs;
  EXPECT_EQ(LongestCopy(m, lib, 0.01, &runs), 300);
  EXPECT_EQ(runs[299], 300);
  EXPECT_LT(runs[499], 5);
  // Another take is no copy of the library.
  EXPECT_LT(LongestCopy(Track(*take2_), lib, 0.01), 10);
  const std::vector<RoleTrack> refs = {Track(*take2_)};
  auto c = Compare(m, refs, nullptr, lib);
  ASSERT_TRUE(c.ok());
  EXPECT_NEAR(c->longest_copy_s, 10.0, 1e-5);  // 300 frames of 0.0333333 s
  EXPECT_NEAR(c->longest_copy_fraction, 0.6, 1e-9);
  EXPECT_NEAR(c->copied_fraction, 0.6, 1e-9);
  EXPECT_NEAR(c->copy_frame_fraction, 0.6, 0.02);
}

TEST_F(Beat2, CrossSkeletonComparisonIsFinite) {
  const motion::Clip bandai = Read(kBandai);
  const std::vector<RoleTrack> refs = {Track(*take2_)};
  auto c = Compare(Track(bandai), refs, nullptr, {});
  ASSERT_TRUE(c.ok()) << c.status();
  for (double v : {c->hellinger_speed, c->hellinger_accel, c->fd_kinetic, c->generated.jerk_mean_m_s3}) {
    EXPECT_TRUE(std::isfinite(v));
    EXPECT_GT(v, 0);
  }
}

TEST_F(Beat2, BeatsOfRealMotion) {
  const RoleTrack t = Track(*take1_);
  const std::vector<double> beats = KinematicBeats(t);
  // A speaker gesturing freely: roughly one apex per second or more.
  EXPECT_GT(beats.size(), 40u);
  for (size_t i = 1; i < beats.size(); ++i) EXPECT_GT(beats[i], beats[i - 1]);
  // Accents exactly 0.1 s after every beat are all in the window; 0.5 s
  // after, none (the beats are at least 2 frames apart, the window 0.25 s).
  std::vector<double> a1, a2;
  for (double b : beats) {
    a1.push_back(b + 0.1);
  }
  AudioEvents audio{{}, a1};
  const ClipMeasures m = MeasureClip(t, &audio);
  EXPECT_DOUBLE_EQ(m.accent_sync_fraction, 1.0);
  EXPECT_LT(m.accent_sync_chance, 0.8);
  EXPECT_DOUBLE_EQ(SyncFraction(std::vector<double>{1.0}, std::vector<double>{0.5}, -0.03, 0.22), 0.0);
}

TEST(Parts, HellingerFrechetAndBeatAlignment) {
  const std::vector<double> p = {1, 2, 3, 0}, q = {2, 4, 6, 0}, r = {0, 0, 0, 5};
  EXPECT_NEAR(HellingerDistance(p, q), 0, 1e-12);
  EXPECT_NEAR(HellingerDistance(p, r), 1, 1e-12);
  const std::vector<double> h = Histogram(std::vector<double>{0.01, 0.06, 0.07, 9.0}, 0.05, 3);
  EXPECT_EQ(h, (std::vector<double>{1, 2, 0, 1}));
  Eigen::MatrixXd s(2, 2);
  s << 2, 0.5, 0.5, 1;
  Eigen::VectorXd m1(2), m2(2);
  m1 << 0, 0;
  m2 << 3, 4;
  EXPECT_NEAR(FrechetDistance(m1, s, m1, s), 0, 1e-9);
  EXPECT_NEAR(FrechetDistance(m1, s, m2, s), 25, 1e-9);
  // Diagonal covariances: (sqrt(a) - sqrt(b))^2 per dimension.
  const Eigen::MatrixXd a = Eigen::Vector2d(4, 1).asDiagonal(), b = Eigen::Vector2d(1, 9).asDiagonal();
  EXPECT_NEAR(FrechetDistance(m1, a, m1, b), 1 + 4, 1e-9);
  EXPECT_DOUBLE_EQ(BeatAlignment(std::vector<double>{1.0, 2.0}, std::vector<double>{1.0, 2.0}, 0.1), 1.0);
  EXPECT_NEAR(BeatAlignment(std::vector<double>{1.0}, std::vector<double>{1.1}, 0.1), std::exp(-0.5), 1e-12);
  EXPECT_EQ(BeatAlignment(std::vector<double>{1.0}, std::vector<double>{}, 0.1), 0);
}

TEST(Compare, RefusesWhatItCannotJudge) {
  RoleTrack t;
  t.p = Eigen::MatrixXd::Zero(10, 3 * kNumRoles);
  EXPECT_FALSE(Compare(t, {}, nullptr, {}).ok());
  const std::vector<RoleTrack> refs = {t};
  auto c = Compare(t, refs, nullptr, {});
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("generated"), std::string::npos) << c.status();
  const motion::Clip bandai = Read(kBandai);
  EXPECT_FALSE(ExtractRoleTrack(bandai, 0).ok());
  EXPECT_FALSE(ExtractRoleTrack(bandai, 0.01, -1).ok());
}

}  // namespace
}  // namespace kinemo::evaluation
