// `kinemo motion check FILE.bvh [--reference DIR] --json` run as a process on
// real Bandai and CMU clips of tests/data, and on the motion `kinemo gestures`
// makes for LibriVox speech with and without planted feet.
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/testing/process.h"

namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

// `kinemo ARGS...` to its exit code (-1 if it could not run); its output in *out.
int Kinemo(const kinemo::testing::TempDir& dir, std::vector<std::string> args, std::string* out) {
  args.insert(args.begin(), std::string(KINEMO_BINARY_DIR) + "/services/cli/kinemo");
  const auto rc = kinemo::testing::ChildProcess::Run(args, dir.File("kinemo.log"), std::chrono::minutes(5), out);
  EXPECT_TRUE(rc.ok()) << rc.status();
  return rc.ok() ? *rc : -1;
}

// `kinemo motion check ARGS... --json`, parsed.
nlohmann::json Check(const kinemo::testing::TempDir& dir, std::vector<std::string> args) {
  args.insert(args.begin(), {"motion", "check"});
  args.push_back("--json");
  std::string out;
  const int rc = Kinemo(dir, args, &out);
  EXPECT_EQ(rc, 0) << out;
  return rc == 0 ? nlohmann::json::parse(out) : nlohmann::json();
}

TEST(MotionCheckCli, SourceClipStandsStill) {
  kinemo::testing::TempDir dir;
  const nlohmann::json m = Check(dir, {kData + "/motion/dataset-1_bye_normal_001.bvh", "--meters-per-unit", "0.01",
                             "--reference", kData + "/planner_gesture"});
  for (const char* k : {"foot_slide_p95_m_s", "min_foot_height_m", "max_float_m", "hips_path_m", "hips_drift_m",
                        "contact_fraction", "speed_outlier_frames", "worst_joint", "worst_joint_dps",
                        "worst_joint_limit_dps"}) {
    ASSERT_TRUE(m.contains(k)) << k;
  }
  EXPECT_LT(m["foot_slide_p95_m_s"].get<double>(), 0.005);
  // Bandai soles stand 2-3 cm above y = 0.
  EXPECT_GT(m["min_foot_height_m"].get<double>(), 0.015);
  EXPECT_LT(m["max_float_m"].get<double>(), 0.035);
  EXPECT_LT(m["hips_drift_m"].get<double>(), 0.05);
  EXPECT_DOUBLE_EQ(m["contact_fraction"].get<double>(), 1.0);
  EXPECT_EQ(m["reference_clips"].get<int>(), 5);
  EXPECT_FALSE(m["worst_joint"].get<std::string>().empty());
}

TEST(MotionCheckCli, WalkTravelsAndSeveralFilesGiveAnArray) {
  kinemo::testing::TempDir dir;
  const nlohmann::json m = Check(dir, {kData + "/planner_locomotion/cmu_007_01.bvh", kData + "/motion/dataset-1_bye_normal_001.bvh",
                             "--meters-per-unit", "0.01"});
  ASSERT_TRUE(m.is_array());
  ASSERT_EQ(m.size(), 2u);
  // CMU 7/1 walks about 4 m; each foot stands about half the time.
  EXPECT_GT(m[0]["hips_drift_m"].get<double>(), 3.0);
  EXPECT_NEAR(m[0]["hips_path_m"].get<double>(), m[0]["hips_drift_m"].get<double>(), 0.2);
  EXPECT_NEAR(m[0]["contact_fraction"].get<double>(), 0.5, 0.15);
  EXPECT_FALSE(m[0].contains("speed_outlier_frames"));
  EXPECT_LT(m[1]["hips_drift_m"].get<double>(), 0.05);
}

TEST(MotionCheckCli, GesturesPlantTheFeet) {
  kinemo::testing::TempDir dir;
  std::string out;
  const std::string wav = kData + "/speech/sense_and_sensibility_01_austen_64kb-0890.wav";
  for (const bool plant : {true, false}) {
    std::vector<std::string> args = {"gestures", wav, "--library", kData + "/planner_gesture", "--algorithm",
                                     "gmg", "--no-recognize", "-o", dir.File(plant ? "planted.bvh" : "raw.bvh")};
    if (!plant) args.push_back("--no-plant-feet");
    ASSERT_EQ(Kinemo(dir, args, &out), 0) << out;
  }
  const nlohmann::json planted = Check(dir, {dir.File("planted.bvh"), "--reference", kData + "/planner_gesture"});
  const nlohmann::json raw = Check(dir, {dir.File("raw.bvh"), "--reference", kData + "/planner_gesture"});
  EXPECT_LT(planted["foot_slide_p95_m_s"].get<double>(), 0.03);
  EXPECT_LT(planted["max_float_m"].get<double>(), 0.02);
  EXPECT_GT(raw["foot_slide_p95_m_s"].get<double>(), 2 * planted["foot_slide_p95_m_s"].get<double>() + 0.005);
  EXPECT_GT(raw["max_float_m"].get<double>(), 0.02);
  // Planting touches the legs only: the outliers of the synthesis remain.
  EXPECT_LE(planted["speed_outlier_frames"].get<int>(), raw["speed_outlier_frames"].get<int>() + 5);
}

TEST(MotionCheckCli, BadInputExitsWithTwo) {
  kinemo::testing::TempDir dir;
  std::string out;
  EXPECT_EQ(Kinemo(dir, {"motion", "check", dir.File("missing.bvh"), "--json"}, &out), 2);
  EXPECT_NE(out.find("missing.bvh"), std::string::npos) << out;
  // A truncated real file.
  std::ifstream in(kData + "/motion/dataset-1_bye_normal_001.bvh");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(dir.File("cut.bvh")) << text.substr(0, text.size() / 3);
  EXPECT_EQ(Kinemo(dir, {"motion", "check", dir.File("cut.bvh")}, &out), 2);
  EXPECT_NE(out.find("cut.bvh"), std::string::npos) << out;
  // A reference folder without clips.
  EXPECT_EQ(Kinemo(dir, {"motion", "check", kData + "/motion/dataset-1_bye_normal_001.bvh", "--reference", kData + "/speech"},
                   &out),
            2);
  EXPECT_NE(out.find("--reference"), std::string::npos) << out;
  // A reference with no joint in common (CMU iClone vs Bandai).
  EXPECT_EQ(Kinemo(dir,
                   {"motion", "check", kData + "/motion/dataset-1_bye_normal_001.bvh", "--reference",
                    kData + "/planner_locomotion/cmu_007_01.bvh"},
                   &out),
            2);
  EXPECT_NE(out.find("reference"), std::string::npos) << out;
}

}  // namespace
