// Motion compare (common/evaluation) on real motion capture: the BEAT2 takes
// of tests/data/paired/beat2 (SMPL-X, 55 joints, centimetres) and Bandai
// clips (22 joints).
#include "common/evaluation/motion_compare.h"

#include <cmath>
#include <numeric>
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
  EXPECT_NEAR(c->genea_hellinger_speed, 0, 1e-6);
  EXPECT_NEAR(c->genea_hellinger_accel, 0, 1e-6);
  EXPECT_NEAR(c->fid_k, 0, 1e-6);
  EXPECT_NEAR(c->fid_k_bailando, 0, 1e-6);
  EXPECT_EQ(c->fid_windows, 62);  // 63.5 s: 2 s windows every 1 s
  EXPECT_DOUBLE_EQ(c->generated.jerk_mean_m_s3, c->reference.jerk_mean_m_s3);
  // This speaker's figures (docs/evaluation.md): wrist speed mean 0.35-0.57 m/s.
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
  EXPECT_LT(natural->genea_hellinger_speed, 0.3);
  EXPECT_LT(natural->genea_hellinger_accel, 0.3);
  EXPECT_GT(dead->genea_hellinger_speed, 0.9);
  EXPECT_GT(dead->fid_k, 2 * natural->fid_k);
  // With the windows of both clips pooled for the z-scores, FID_k is
  // symmetric: take 2 judged against take 1 scores the same.
  const std::vector<RoleTrack> refs1 = {t1};
  auto back = Compare(t2, refs1, nullptr, {});
  ASSERT_TRUE(back.ok());
  EXPECT_NEAR(back->fid_k, natural->fid_k, 1e-6 * natural->fid_k);
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
  EXPECT_NEAR(a->fid_k, b->fid_k, 1e-6);
  EXPECT_NEAR(a->genea_hellinger_speed, b->genea_hellinger_speed, 1e-9);
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

// ---- The published measures on small tracks whose values are computed by
// hand. A synthetic track: every role at rest at a plausible place, the
// hips along x (so the near-copy heading is fixed).
RoleTrack RestTrack(int frames) {
  RoleTrack t;
  t.p = Eigen::MatrixXd::Zero(frames, 3 * kNumRoles);
  const std::array<Eigen::Vector3d, kNumRoles> at = {
      Eigen::Vector3d(0, 1.0, 0),     Eigen::Vector3d(0, 1.7, 0),     Eigen::Vector3d(0.2, 1.45, 0),
      Eigen::Vector3d(-0.2, 1.45, 0), Eigen::Vector3d(0.25, 1.2, 0),  Eigen::Vector3d(-0.25, 1.2, 0),
      Eigen::Vector3d(0.25, 0.95, 0), Eigen::Vector3d(-0.25, 0.95, 0), Eigen::Vector3d(0.1, 0.08, 0),
      Eigen::Vector3d(-0.1, 0.08, 0), Eigen::Vector3d(0.1, 0.5, 0),   Eigen::Vector3d(-0.1, 0.5, 0),
      Eigen::Vector3d(0.1, 0.95, 0),  Eigen::Vector3d(-0.1, 0.95, 0)};
  for (int f = 0; f < frames; ++f) {
    for (int r = 0; r < kNumRoles; ++r) t.p.block<1, 3>(f, 3 * r) = at[static_cast<size_t>(r)].transpose();
  }
  return t;
}

void Set(RoleTrack* t, int f, int role, const Eigen::Vector3d& x) { t->p.block<1, 3>(f, 3 * role) = x.transpose(); }

TEST(Published, GeneaHellingerOfWristsAtKnownSpeeds) {
  // Generated: left wrist 1.525 cm per frame, right 3.025 (bins 30 and 60 of
  // 0.05 cm); reference: left 1.525, right 4.025 (bin 80). Half of each
  // histogram in a shared bin: H = sqrt(1 − sqrt(0.5 · 0.5)) = sqrt(0.5).
  const int n = 90;
  RoleTrack gen = RestTrack(n), ref = RestTrack(n);
  for (int f = 0; f < n; ++f) {
    Set(&gen, f, kLeftWrist, Eigen::Vector3d(0.25 + 0.01525 * f, 0.95, 0));
    Set(&gen, f, kRightWrist, Eigen::Vector3d(-0.25, 0.95, 0.03025 * f));
    Set(&ref, f, kLeftWrist, Eigen::Vector3d(0.25 + 0.01525 * f, 0.95, 0));
    Set(&ref, f, kRightWrist, Eigen::Vector3d(-0.25, 0.95 + 0.04025 * f, 0));
  }
  const std::array<int, 2> wrists = {kLeftWrist, kRightWrist};
  const std::vector<double> h = GeneaHistogram(gen, wrists, 1, 0.05, 49);
  ASSERT_EQ(h.size(), 980u);  // numpy.arange(0, 49.05, 0.05): 981 edges
  EXPECT_EQ(h[30], n - 1);
  EXPECT_EQ(h[60], n - 1);
  EXPECT_EQ(std::accumulate(h.begin(), h.end(), 0.0), 2.0 * (n - 1));
  // Constant speeds: every second difference is 0 (bin 0).
  EXPECT_EQ(GeneaHistogram(gen, wrists, 2, 0.05, 49)[0], 2.0 * (n - 2));
  const std::vector<RoleTrack> refs = {ref};
  auto c = Compare(gen, refs, nullptr, {});
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_NEAR(c->genea_hellinger_speed, std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(c->genea_hellinger_accel, 0, 1e-12);
  // Beyond GENEA's 49-unit range a value is dropped, as numpy.histogram does.
  RoleTrack jump = RestTrack(3);
  Set(&jump, 1, kLeftWrist, Eigen::Vector3d(0.25 + 0.5, 0.95, 0));  // 50 cm in a frame
  const std::array<int, 1> left = {kLeftWrist};
  const std::vector<double> hj = GeneaHistogram(jump, left, 1, 0.05, 49);
  EXPECT_EQ(std::accumulate(hj.begin(), hj.end(), 0.0), 0.0);
}

TEST(Published, AistKineticFeaturesOfUniformMotion) {
  // A joint moving at (0.3, 0.4, 0) m/s: every averaged velocity is that, so
  // the horizontal kinetic energy is 0.09, the vertical 0.16, the energy
  // expenditure 0. A joint accelerating at (0, 0, 2) m/s² from rest: its
  // averaged accelerations are all (0, 0, 2): expenditure 2.
  const int n = 30;
  RoleTrack t = RestTrack(n);
  for (int f = 0; f < n; ++f) {
    const double s = f / 30.0;
    Set(&t, f, kLeftWrist, Eigen::Vector3d(0.25 + 0.3 * s, 0.95 + 0.4 * s, 0));
    Set(&t, f, kRightWrist, Eigen::Vector3d(-0.25, 0.95, 0.5 * 2 * s * s));
  }
  const std::array<int, 3> roles = {kLeftWrist, kRightWrist, kHead};
  const Eigen::VectorXd k = AistKineticFeatures(t, 0, n, roles);
  ASSERT_EQ(k.size(), 9);
  EXPECT_NEAR(k(0), 0.09, 1e-9);
  EXPECT_NEAR(k(1), 0.16, 1e-9);
  EXPECT_NEAR(k(2), 0, 1e-9);
  EXPECT_NEAR(k(5), 2, 1e-6);
  EXPECT_NEAR(k(6), 0, 1e-12);  // the head is still
  EXPECT_NEAR(k(7), 0, 1e-12);
  EXPECT_NEAR(k(8), 0, 1e-12);
  EXPECT_EQ(FidRoles().size(), static_cast<size_t>(kNumRoles));
}

TEST(Published, EmageBeatsAndBeatConsistency) {
  // Both wrists swing along x, x = 0.2 sin(π t), while rising at 0.1 m/s:
  // speed sqrt((0.2π cos πt)² + 0.1²), minimal (0.1 m/s) at t = 0.5, 1.5, ...
  // Every other role is still (no beats).
  const int n = 150;  // 5 s
  RoleTrack t = RestTrack(n);
  for (int f = 0; f < n; ++f) {
    const double s = f / 30.0;
    for (int side = 0; side < 2; ++side) {
      Set(&t, f, kLeftWrist + side, Eigen::Vector3d((side ? -0.25 : 0.25) + 0.2 * std::sin(M_PI * s), 0.95 + 0.1 * s, 0));
    }
  }
  const std::vector<double> beats = EmageMotionBeats(t, kLeftWrist, 7, 0.1 * MeanSpeed(t, kLeftWrist));
  ASSERT_EQ(beats.size(), 5u);
  for (size_t i = 0; i < beats.size(); ++i) EXPECT_NEAR(beats[i], 0.5 + static_cast<double>(i), 1e-9);
  // A still joint has no beats; a threshold above 0.1 m/s removes them all.
  EXPECT_TRUE(EmageMotionBeats(t, kHead, 7, 0).empty());
  EXPECT_TRUE(EmageMotionBeats(t, kLeftWrist, 7, 0.11).empty());
  // Onsets 0.1 s from a beat and on a beat: (exp(−0.1²/(2·0.3²)) + 1) / 2.
  const std::vector<double> onsets = {0.6, 2.5};
  const double g = (std::exp(-0.01 / 0.18) + 1) / 2;
  EXPECT_NEAR(GaussianAlignment(beats, onsets, 0.3), g, 1e-12);
  EXPECT_EQ(GaussianAlignment({}, onsets, 0.3), 0);
  // BC averages over the 7 beat roles: the two wrists have it, the others 0.
  AudioEvents audio;
  audio.audio_onsets_s = {0.6, 2.5, 7.0};  // the last is after the motion: ignored
  const std::vector<RoleTrack> refs = {t};
  auto c = Compare(t, refs, &audio, {});
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(BeatRoles().size(), 7u);
  EXPECT_EQ(c->audio_onsets, 2);
  EXPECT_NEAR(c->beat_consistency, 2 * g / 7, 1e-12);
  EXPECT_NEAR(c->reference_beat_consistency, 2 * g / 7, 1e-12);
}

TEST(Published, L1DiversityAnkleLiftAndEnvelopes) {
  // The left wrist jumps between ±0.1 m (x) about its mean every frame: mean
  // absolute deviation 0.1 in one coordinate, every other coordinate still.
  const int n = 90;
  RoleTrack t = RestTrack(n);
  for (int f = 0; f < n; ++f) Set(&t, f, kLeftWrist, Eigen::Vector3d(0.25 + (f % 2 ? 0.1 : -0.1), 0.95, 0));
  EXPECT_NEAR(L1Diversity(t), 0.1, 1e-12);
  EXPECT_NEAR(L1Diversity(RestTrack(n)), 0, 1e-12);
  // The left ankle 0.12 m above its lowest for 9 frames, 0.08 m for 9 more;
  // the right ankle still: 9 of 90 frames.
  RoleTrack feet = RestTrack(n);
  for (int f = 10; f < 19; ++f) Set(&feet, f, kLeftFoot, Eigen::Vector3d(0.1, 0.08 + 0.12, 0));
  for (int f = 30; f < 39; ++f) Set(&feet, f, kLeftFoot, Eigen::Vector3d(0.1, 0.08 + 0.08, 0));
  EXPECT_NEAR(AnkleLiftShare(feet, 0.10), 0.1, 1e-12);
  const std::vector<RoleTrack> refs = {RestTrack(n)};
  auto c = Compare(feet, refs, nullptr, {});
  ASSERT_TRUE(c.ok());
  EXPECT_NEAR(c->generated.ankle_lift_share, 0.1, 1e-12);
  EXPECT_NEAR(c->reference.ankle_lift_share, 0, 1e-12);
  // Envelopes: the left wrist moves at 0.3 m/s for 0.5 s, rests 0.5 s, ...;
  // the mean of both wrists is 0.15 m/s in the moving bins.
  RoleTrack env = RestTrack(n);
  double x = 0.25;
  for (int f = 1; f < n; ++f) {
    if (((f - 1) / 15) % 2 == 0) x += 0.01;
    Set(&env, f, kLeftWrist, Eigen::Vector3d(x, 0.95, 0));
  }
  const std::vector<double> e = HandSpeedEnvelope(env, 0.5);
  ASSERT_EQ(e.size(), 5u);  // 89 speed samples: five whole bins of 15
  for (size_t i = 0; i < e.size(); ++i) EXPECT_NEAR(e[i], i % 2 ? 0 : 0.15, 1e-12);
  // Loudness: bins of 0.5 s at 1 kHz, amplitude ±0.5 (RMS 0.5: −6.02 dB),
  // ±0.05 (−26.02 dB), silence (floored 60 dB below the loudest: −66.02 dB).
  std::vector<float> y(1600, 0.0f);
  for (int i = 0; i < 500; ++i) y[static_cast<size_t>(i)] = i % 2 ? 0.5f : -0.5f;
  for (int i = 500; i < 1000; ++i) y[static_cast<size_t>(i)] = i % 2 ? 0.05f : -0.05f;
  const std::vector<double> loud = LoudnessEnvelope(y, 1000, 0.5);
  ASSERT_EQ(loud.size(), 3u);  // the last 100 samples are a partial bin
  EXPECT_NEAR(loud[0], 20 * std::log10(0.5), 1e-6);
  EXPECT_NEAR(loud[1], 20 * std::log10(0.05), 1e-5);
  EXPECT_NEAR(loud[2], 20 * std::log10(0.5e-3), 1e-6);
  const std::vector<double> a = {1, 2, 3, 4}, b = {2, 4, 6, 8}, d = {4, 3, 2, 1};
  EXPECT_NEAR(PearsonCorrelation(a, b), 1, 1e-12);
  EXPECT_NEAR(PearsonCorrelation(a, d), -1, 1e-12);
  EXPECT_EQ(PearsonCorrelation(a, std::vector<double>{1, 1, 1, 1}), 0);
}

// kinemo's own: the knees' jerk. The left knee follows x = c·f³ (c = 1 mm):
// every third difference is 6c = 6 mm, i.e. 0.006 · 30³ = 162 m/s³ at 30
// fps; the right knee is still. Pooled over both knees: 81.
TEST(KinemoMeasures, KneeJerkOfACubicPath) {
  const int n = 45;  // Compare judges 1.5 s and more
  RoleTrack t = RestTrack(n);
  t.frame_time_s = 1.0 / 30;
  for (int f = 0; f < n; ++f) Set(&t, f, kLeftKnee, Eigen::Vector3d(0.1 + 0.001 * f * f * f, 0.5, 0));
  const std::vector<RoleTrack> refs = {RestTrack(n)};
  auto c = Compare(t, refs, nullptr, {});
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_NEAR(c->generated.knee_jerk_mean_m_s3, 81, 1e-6);
  EXPECT_NEAR(c->reference.knee_jerk_mean_m_s3, 0, 1e-12);
  EXPECT_NEAR(c->generated.jerk_mean_m_s3, 0, 1e-12);  // the wrists are still
}

TEST(Published, AudioOnsetsOfNoiseBursts) {
  // Silence with 0.3 s bursts of white noise starting at samples 512·t for
  // t = 32, 64, 96 (16 kHz). STFT frame u is centred at sample 512·u, so
  // frame t − 1 is the first to see a burst (its last 512 samples); librosa's
  // envelope reports the rise into frame u at u + 2 (lag 1 + n_fft / (2 hop)
  // = 3 frames after the difference u − 1 → u): onsets at (t + 1) · 0.032 s.
  // Inside a burst and at its end (every band falls) nothing rises enough.
  const int sr = 16000;
  std::vector<float> y(static_cast<size_t>(4 * sr), 0.0f);
  uint32_t state = 12345;
  for (int t : {32, 64, 96}) {
    for (int i = 0; i < static_cast<int>(0.3 * sr); ++i) {
      state = state * 1664525u + 1013904223u;
      y[static_cast<size_t>(512 * t + i)] = static_cast<float>(0.5 * (state / 4294967296.0 * 2 - 1));
    }
  }
  auto onsets = AudioOnsets(y, sr);
  ASSERT_TRUE(onsets.ok()) << onsets.status();
  std::string got;
  for (double o : *onsets) got += std::to_string(o) + " ";
  ASSERT_EQ(onsets->size(), 3u) << got;
  EXPECT_NEAR((*onsets)[0], 33 * 0.032, 1e-9);
  EXPECT_NEAR((*onsets)[1], 65 * 0.032, 1e-9);
  EXPECT_NEAR((*onsets)[2], 97 * 0.032, 1e-9);
  // Silence has no onsets; a bad rate is refused.
  EXPECT_TRUE(AudioOnsets(std::vector<float>(16000, 0.0f), sr)->empty());
  EXPECT_FALSE(AudioOnsets(y, 10).ok());
}

// A library track whose wrists circle (radius 0.2 m, 1 s per turn) and its
// playback at `speed`× by linear interpolation between library frames.
RoleTrack Circling(int frames, double phase = 0) {
  RoleTrack t = RestTrack(frames);
  for (int f = 0; f < frames; ++f) {
    const double a = 2 * M_PI * f / 30.0 + phase;
    Set(&t, f, kLeftWrist, Eigen::Vector3d(0.25 + 0.2 * std::cos(a), 1.1 + 0.2 * std::sin(a), 0.2));
    Set(&t, f, kRightWrist, Eigen::Vector3d(-0.25 - 0.2 * std::cos(a), 1.1 + 0.2 * std::sin(a), 0.2));
  }
  return t;
}
RoleTrack Played(const RoleTrack& lib, int first, double speed, int frames) {
  RoleTrack t;
  t.p.resize(frames, lib.p.cols());
  for (int k = 0; k < frames; ++k) {
    const double g = first + speed * k;
    const int g0 = static_cast<int>(std::floor(g));
    const double w = g - g0;
    t.p.row(k) = (1 - w) * lib.p.row(g0) + w * lib.p.row(std::min(g0 + 1, lib.num_frames() - 1));
  }
  return t;
}

TEST(NearCopies, FindsTimeWarpedPlaybackAndNotFasterOrOtherMotion) {
  const std::vector<RoleTrack> lib = {RestTrack(30), Circling(400)};
  // 200 output frames of library frames 10, 11.5, 13, ...: steps of 1 and 2,
  // each in-between frame within 1 cm of a library frame at the wrists.
  const RoleTrack warped = Played(lib[1], 10, 1.5, 200);
  NearCopyResult r = NearCopies(warped, lib, 0.03, 2, 60);
  EXPECT_EQ(r.longest, 200);
  EXPECT_EQ(r.frames_in_long_runs, 200);
  EXPECT_EQ(r.run_lengths[99], 100);
  // The old detector sees no copy in it beyond single frames.
  EXPECT_LE(LongestCopy(warped, lib, 0.01), 1);
  // Slowed down to 0.5x (steps 0 and 1): found too.
  EXPECT_EQ(NearCopies(Played(lib[1], 0, 0.5, 150), lib, 0.03, 2, 60).longest, 150);
  // At 3x the library runs away from any run allowing steps up to 2.
  r = NearCopies(Played(lib[1], 0, 3.0, 120), lib, 0.03, 2, 60);
  EXPECT_LT(r.longest, 30);
  EXPECT_EQ(r.frames_in_long_runs, 0);
  // The wrists 0.15 m further forward (off the circles' plane): a mean
  // error of at least 2 × 0.15 / 7 = 4.3 cm against any library frame.
  RoleTrack higher = Played(lib[1], 10, 1.0, 100);
  for (int f = 0; f < higher.num_frames(); ++f) {
    for (int role : {kLeftWrist, kRightWrist}) higher.p(f, 3 * role + 2) += 0.15;
  }
  EXPECT_EQ(NearCopies(higher, lib, 0.03, 2, 60).longest, 0);
  // The whole body turned by 90° about the vertical and moved: still a copy.
  RoleTrack turned = Played(lib[1], 10, 1.0, 100);
  for (int f = 0; f < turned.num_frames(); ++f) {
    for (int role = 0; role < kNumRoles; ++role) {
      const Eigen::Vector3d x = turned.At(f, role);
      Set(&turned, f, role, Eigen::Vector3d(x.z() + 3, x.y(), -x.x() - 1));
    }
  }
  EXPECT_EQ(NearCopies(turned, lib, 0.03, 2, 60).longest, 100);
  // Through Compare: share and longest run in seconds.
  const std::vector<RoleTrack> refs = {lib[1]};
  auto c = Compare(warped, refs, nullptr, lib);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_NEAR(c->longest_near_copy_s, 200 / 30.0, 1e-9);
  EXPECT_NEAR(c->near_copy_share_over_2s, 1.0, 1e-12);
}

TEST_F(Beat2, NearCopiesOfARealTakeTimeWarped) {
  // Take 1's frames 300..599 played 1.5x faster (resampled to 20 fps and
  // played at 30), then 200 frames of take 2: the first 200 frames are a copy.
  const std::vector<RoleTrack> lib = {Track(*take1_)};
  auto fast = motion::Resample(Cut(*take1_, 300, 300), 20);
  ASSERT_TRUE(fast.ok()) << fast.status();
  motion::Clip warped = *fast;
  warped.frame_time_s = 1.0 / 30;
  ASSERT_EQ(warped.num_frames(), 200);
  warped.frames.conservativeResize(400, Eigen::NoChange);
  warped.frames.bottomRows(200) = take2_->frames.middleRows(900, 200);
  const RoleTrack w = Track(warped);
  const NearCopyResult r = NearCopies(w, lib, 0.03, 2, 60);
  EXPECT_GE(r.run_lengths[199], 195);
  EXPECT_GE(r.longest, 195);
  EXPECT_LE(r.longest, 215);
  // The old detector (every joint within 1 cm, consecutive library frames)
  // loses the copy wherever the hands move faster than ~0.6 m/s.
  EXPECT_LT(LongestCopy(w, lib, 0.01), 100);
}

TEST_F(Beat2, RepeatsOfLibraryMaterial) {
  // Take 1's frames 300..399 shown twice in a row, against take 1 as the
  // library. A frame repeats when it lies in a run of 15 frames or more
  // (repeat_gap / 2) playing the library on, over library frames a run
  // played 30 frames (repeat_gap) or more before. The second showing starts
  // a new run (library frame 399 -> 300): its first 14 frames are in no run
  // of 15 yet, the other 86 play frames 314..399 again, 100 output frames
  // after their first showing: 86 repeated frames. The first showing
  // repeats nothing.
  const std::vector<RoleTrack> lib = {Track(*take1_)};
  motion::Clip twice = Cut(*take1_, 300, 100);
  twice.frames.conservativeResize(200, Eigen::NoChange);
  twice.frames.bottomRows(100) = take1_->frames.middleRows(300, 100);
  const NearCopyResult r = NearCopies(Track(twice), lib, 0.03, 2, 60, 30);
  EXPECT_EQ(r.frames_repeated, 86);
  EXPECT_EQ(NearCopies(Track(Cut(*take1_, 300, 100)), lib, 0.03, 2, 60, 30).frames_repeated, 0);
  // The whole take against itself: the speaker traces a stretch of his own
  // motion again (within 3 cm mean joint error for 0.5 s) now and then.
  const NearCopyResult self = NearCopies(Track(*take1_), lib, 0.03, 2, 60, 30);
  std::printf("take 1 against itself: %d of %d frames play a stretch of it again\n", self.frames_repeated,
              take1_->num_frames());
  EXPECT_LT(self.frames_repeated, take1_->num_frames() / 20);
  // Through Compare: the share of the output.
  const std::vector<RoleTrack> refs = {Track(*take2_)};
  auto c = Compare(Track(twice), refs, nullptr, lib);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_NEAR(c->library_repeat_share, 86 / 200.0, 1e-12);
}

TEST(Compare, RefusesWhatItCannotJudge) {
  RoleTrack t;
  t.p = Eigen::MatrixXd::Zero(10, 3 * kNumRoles);
  EXPECT_FALSE(Compare(t, {}, nullptr, {}).ok());
  const std::vector<RoleTrack> refs = {t};
  auto c = Compare(t, refs, nullptr, {});
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("generated"), std::string::npos) << c.status();
  // 2.5 s: judged, but one window of 2 s fits no Gaussian: FID_k is NaN.
  const std::vector<RoleTrack> rest = {RestTrack(300)};
  auto shortish = Compare(RestTrack(75), rest, nullptr, {});
  ASSERT_TRUE(shortish.ok()) << shortish.status();
  EXPECT_TRUE(std::isnan(shortish->fid_k));
  EXPECT_EQ(shortish->fid_windows, 1);
  const motion::Clip bandai = Read(kBandai);
  EXPECT_FALSE(ExtractRoleTrack(bandai, 0).ok());
  EXPECT_FALSE(ExtractRoleTrack(bandai, 0.01, -1).ok());
}

}  // namespace
}  // namespace kinemo::evaluation
