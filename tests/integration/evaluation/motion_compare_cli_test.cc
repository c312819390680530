// `kinemo motion compare GEN.bvh --reference REF.bvh --audio WAV --library
// LIB --json` run as a process on the real BEAT2 takes (SMPL-X) and Bandai
// clips of tests/data: one take judged against the other, a cross-skeleton
// comparison, explicit scales, and bad input.
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/testing/process.h"

namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;
const std::string kBeat = kData + "/paired/beat2/";

int Kinemo(const kinemo::testing::TempDir& dir, std::vector<std::string> args, std::string* out) {
  args.insert(args.begin(), std::string(KINEMO_BINARY_DIR) + "/services/cli/kinemo");
  const auto rc = kinemo::testing::ChildProcess::Run(args, dir.File("kinemo.log"), std::chrono::minutes(5), out);
  EXPECT_TRUE(rc.ok()) << rc.status();
  return rc.ok() ? *rc : -1;
}

nlohmann::json Compare(const kinemo::testing::TempDir& dir, std::vector<std::string> args) {
  args.insert(args.begin(), {"motion", "compare"});
  args.push_back("--json");
  std::string out;
  const int rc = Kinemo(dir, args, &out);
  EXPECT_EQ(rc, 0) << out;
  return rc == 0 ? nlohmann::json::parse(out) : nlohmann::json();
}

TEST(MotionCompareCli, OneTakeAgainstTheOther) {
  kinemo::testing::TempDir dir;
  const nlohmann::json m = Compare(dir, {kBeat + "2_scott_0_1_1.bvh", "--reference", kBeat + "2_scott_0_2_2.bvh",
                                         "--audio", kBeat + "2_scott_0_2_2.wav", "--library",
                                         kBeat + "2_scott_0_1_1.bvh"});
  for (const char* k : {"hellinger_speed", "hellinger_accel", "fd_kinetic", "jerk_mean_m_s3", "hand_speed_mean_m_s",
                        "hand_speed_p95_m_s", "hands_moving_fraction", "hands_raised_fraction", "beat_consistency",
                        "longest_copy_s", "accent_sync_fraction", "foot_slide_p95_m_s", "reference",
                        "genea_hellinger_speed", "genea_hellinger_accel", "fid_k", "beat_consistency",
                        "beat_consistency_chance", "l1_div", "near_copy_share_over_2s", "longest_near_copy_s",
                        "library_repeat_share", "ankle_lift_share", "kinemo_beat_alignment", "envelope_correlation",
                        "speech_envelope_correlation"}) {
    ASSERT_TRUE(m.contains(k) && !m[k].is_null()) << k;
  }
  // The published measures: the same speaker's two takes are close (the
  // issue's outside tools: Hellinger 0.13-0.18 / 0.06-0.14 between his takes).
  EXPECT_GT(m["genea_hellinger_speed"].get<double>(), 0.02);
  EXPECT_LT(m["genea_hellinger_speed"].get<double>(), 0.3);
  EXPECT_GT(m["genea_hellinger_accel"].get<double>(), 0.02);
  EXPECT_LT(m["genea_hellinger_accel"].get<double>(), 0.3);
  EXPECT_GT(m["fid_k"].get<double>(), 0);
  EXPECT_GT(m["fid_windows"].get<int>(), 55);  // 63.5 s: windows of 2 s every 1 s
  // BC of real motion with its own speech's onsets and with the other take's.
  for (const auto& j : {m, m["reference"]}) {
    const double bc = j["beat_consistency"].get<double>();
    EXPECT_GT(bc, 0.2);
    EXPECT_LT(bc, 1);
  }
  EXPECT_GT(m["audio_onsets"].get<int>(), 100);  // librosa at 16 kHz: dense onsets in speech
  EXPECT_GT(m["l1_div"].get<double>(), 0.1);
  // An ankle lifted more than 10 cm: take 2_2's speaker stands (0.2 % of
  // frames, as the issue measured); in take 1_1 he takes eight steps (the
  // pelvis travels 1 m around frames 250-350): 3.3 %.
  EXPECT_GT(m["ankle_lift_share"].get<double>(), 0.01);
  EXPECT_LT(m["ankle_lift_share"].get<double>(), 0.06);
  EXPECT_LT(m["reference"]["ankle_lift_share"].get<double>(), 0.01);
  // The clip is its own library: a near copy from start to end.
  EXPECT_DOUBLE_EQ(m["near_copy_share_over_2s"].get<double>(), 1.0);
  EXPECT_NEAR(m["longest_near_copy_s"].get<double>(), 1906 / 30.0, 1e-4);
  // The same speaker: close distributions (the issue measured 0.13-0.18 and
  // 0.06-0.14 with its own tools).
  EXPECT_LT(m["hellinger_speed"].get<double>(), 0.3);
  EXPECT_LT(m["hellinger_accel"].get<double>(), 0.3);
  EXPECT_DOUBLE_EQ(m["meters_per_unit"].get<double>(), 0.01);
  // The library is the clip itself: all of it is a copy.
  EXPECT_NEAR(m["longest_copy_s"].get<double>(), 1906 / 30.0, 1e-4);  // frame time 0.03333333
  EXPECT_DOUBLE_EQ(m["longest_copy_fraction"].get<double>(), 1.0);
  const double bc = m["beat_consistency"].get<double>();
  EXPECT_GT(bc, 0);
  EXPECT_LT(bc, 1);
  EXPECT_GT(m["accents"].get<int>(), 20);
  // The speaker shifts his weight: motion check measures 0.06-0.14 m/s on these takes.
  EXPECT_GT(m["foot_slide_p95_m_s"].get<double>(), 0.0);
  EXPECT_LT(m["foot_slide_p95_m_s"].get<double>(), 0.3);
  EXPECT_GT(m["reference"]["foot_slide_p95_m_s"].get<double>(), 0.0);
  EXPECT_GT(m["reference"]["hand_speed_mean_m_s"].get<double>(), 0.3);
}

TEST(MotionCompareCli, ATakeIsNoNearCopyOfTheOtherAndItselfIsZero) {
  kinemo::testing::TempDir dir;
  const std::string take1 = kBeat + "2_scott_0_1_1.bvh", take2 = kBeat + "2_scott_0_2_2.bvh";
  const nlohmann::json m = Compare(dir, {take2, "--reference", take2, "--library", take1});
  // Real motion for other speech is no playback of the first take.
  EXPECT_LT(m["near_copy_share_over_2s"].get<double>(), 0.1);
  EXPECT_LT(m["longest_near_copy_s"].get<double>(), 4);
  // Nor does it play stretches of it twice (a loop): a few traces at most.
  EXPECT_LT(m["library_repeat_share"].get<double>(), 0.05);
  EXPECT_NEAR(m["genea_hellinger_speed"].get<double>(), 0, 1e-6);
  EXPECT_NEAR(m["genea_hellinger_accel"].get<double>(), 0, 1e-6);
  EXPECT_NEAR(m["fid_k"].get<double>(), 0, 1e-6);
  EXPECT_NEAR(m["envelope_correlation"].get<double>(), 1, 1e-12);
  EXPECT_TRUE(m["beat_consistency"].is_null());  // no --audio
}

TEST(MotionCompareCli, BandaiAgainstBeat2AndExplicitScales) {
  kinemo::testing::TempDir dir;
  const std::string bandai = kData + "/planner_gesture/dataset-1_guide_normal_001.bvh";
  const nlohmann::json a = Compare(dir, {bandai, "--reference", kBeat + "2_scott_0_2_2.bvh"});
  const nlohmann::json b = Compare(dir, {bandai, "--reference", kBeat + "2_scott_0_2_2.bvh", "--meters-per-unit",
                                         "0.01", "--reference-meters-per-unit", "0.01"});
  EXPECT_GT(a["fd_kinetic"].get<double>(), 0);
  EXPECT_DOUBLE_EQ(a["fd_kinetic"].get<double>(), b["fd_kinetic"].get<double>());
  EXPECT_TRUE(a["beat_consistency"].is_null());
  EXPECT_TRUE(a["longest_copy_s"].is_null());
  EXPECT_TRUE(a["near_copy_share_over_2s"].is_null());
  EXPECT_TRUE(a["library_repeat_share"].is_null());
  // The clip is shorter than two FID windows of 2 s: no FID_k.
  EXPECT_TRUE(a["fid_k"].is_null());
  // A scale 100x too small: hands 100x slower.
  const nlohmann::json c = Compare(dir, {bandai, "--reference", kBeat + "2_scott_0_2_2.bvh", "--meters-per-unit",
                                         "0.0001"});
  EXPECT_NEAR(c["hand_speed_mean_m_s"].get<double>(), 0.01 * a["hand_speed_mean_m_s"].get<double>(), 1e-9);
}

TEST(MotionCompareCli, BadInputExitsWithTwo) {
  kinemo::testing::TempDir dir;
  std::string out;
  const std::string take = kBeat + "2_scott_0_1_1.bvh";
  EXPECT_EQ(Kinemo(dir, {"motion", "compare", take, "--reference", dir.File("missing.bvh")}, &out), 2);
  EXPECT_NE(out.find("--reference"), std::string::npos) << out;
  EXPECT_EQ(Kinemo(dir, {"motion", "compare", take, "--reference", take, "--audio", dir.File("none.wav")}, &out), 2);
  EXPECT_NE(out.find("--audio"), std::string::npos) << out;
  // A clip shorter than one window (the first 20 frames of a take).
  std::ifstream in(take);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t motion = text.find("MOTION");
  std::string head = text.substr(0, motion) + "MOTION\nFrames: 20\nFrame Time: 0.0333333\n";
  size_t at = text.find('\n', text.find("Frame Time", motion)) + 1;
  for (int k = 0; k < 20; ++k) {
    const size_t end = text.find('\n', at) + 1;
    head += text.substr(at, end - at);
    at = end;
  }
  std::ofstream(dir.File("short.bvh")) << head;
  EXPECT_EQ(Kinemo(dir, {"motion", "compare", dir.File("short.bvh"), "--reference", take}, &out), 2);
  EXPECT_NE(out.find("generated"), std::string::npos) << out;
}

}  // namespace
