// `kinemo crf fig4 --paired` and `kinemo crf bench` run as a user runs them:
// leave-one-take-out on BEAT2's two takes (speech and motion recorded
// together), and the bench on a small real input (a LibriVox recording and
// Bandai clips), which failed before on inputs the model's bounds refused.
#include <cmath>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/testing/process.h"

namespace {

const std::string kData = KINEMO_TEST_DATA_DIR;

int Kinemo(const kinemo::testing::TempDir& dir, std::vector<std::string> args, std::string* out) {
  args.insert(args.begin(), std::string(KINEMO_BINARY_DIR) + "/services/cli/kinemo");
  const auto rc = kinemo::testing::ChildProcess::Run(args, dir.File("kinemo.log"), std::chrono::minutes(8), out);
  EXPECT_TRUE(rc.ok()) << rc.status();
  return rc.ok() ? *rc : -1;
}

TEST(CrfCli, Fig4OnBeat2HoldsEachTakeOutInTurn) {
  kinemo::testing::TempDir dir;
  std::string out;
  ASSERT_EQ(Kinemo(dir, {"crf", "fig4", "--paired", kData + "/paired/beat2", "--states", "6", "--clusters", "6",
                         "--max-window", "2", "--window", "2", "--json", "--csv", dir.File("fig4.csv")},
                   &out),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_EQ(j["pairing"], "recorded together");
  ASSERT_EQ(j["folds"].size(), 2u);
  std::vector<std::string> tests;
  for (const auto& f : j["folds"]) {
    ASSERT_EQ(f["train"].size(), 1u);
    EXPECT_NE(f["train"][0].get<std::string>(), f["test"].get<std::string>());
    tests.push_back(f["test"]);
    EXPECT_GT(f["steps"].get<int>(), 60);
    EXPECT_TRUE(std::isfinite(f["crf_ll_per_step"].get<double>()));
    EXPECT_TRUE(std::isfinite(f["hmm_ll_per_step"].get<double>()));
    ASSERT_EQ(f["by_window"].size(), 2u);
    EXPECT_EQ(f["by_window"][1]["crf_ll_per_step"], f["crf_ll_per_step"]);
  }
  EXPECT_EQ(tests, (std::vector<std::string>{"2_scott_0_1_1", "2_scott_0_2_2"}));
  std::ifstream in(dir.File("fig4.csv"));
  const std::string csv((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(csv.find("recorded together"), std::string::npos);
  EXPECT_NE(csv.find("\n2,"), std::string::npos);

  // One recording cannot be left out: refused, naming the flag.
  EXPECT_EQ(Kinemo(dir, {"crf", "fig4", "--paired", kData + "/speech", "--json"}, &out), 2);
  EXPECT_EQ(Kinemo(dir, {"crf", "fig4", "--paired", kData + "/paired/beat2", "--window", "9"}, &out), 2);
}

TEST(CrfCli, BenchRunsOnSmallRealInput) {
  kinemo::testing::TempDir dir;
  std::string out;
  ASSERT_EQ(Kinemo(dir, {"crf", "bench", "--json", "--minutes", "0.2", "--work-dir", dir.File("bench"), "--speech",
                         kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav", "--gestures",
                         kData + "/planner_gesture/dataset-1_bye_angry_001.bvh",
                         kData + "/planner_gesture/dataset-1_byebye_normal_001.bvh"},
                   &out),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(out);
  for (const char* k : {"train_s_12min_25states", "step_us_p50", "step_us_p99", "training_data_s"}) {
    ASSERT_TRUE(j.contains(k)) << k;
    EXPECT_GT(j[k].get<double>(), 0.0) << k;
  }
  EXPECT_LE(j["step_us_p50"].get<double>(), j["step_us_p99"].get<double>());
  EXPECT_GE(j["training_data_s"].get<double>(), 0.2 * 60 - 8);  // whole recordings, about 12 s
}

}  // namespace
