// `kinemo gmg sweep --json` and `kinemo gestures FILE.wav --library DIR -o OUT.bvh
// --visemes OUT.json --report REPORT.json` run as processes on the real clips of
// tests/data/planner_gesture and LibriVox speech of tests/data/speech.
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/testing/process.h"

namespace {

using Json = nlohmann::json;

const std::string kData = KINEMO_TEST_DATA_DIR;
const std::string kKinemo = std::string(KINEMO_BINARY_DIR) + "/services/cli/kinemo";

int RunCli(const std::vector<std::string>& argv, const std::string& log, std::string* out) {
  auto rc = kinemo::testing::ChildProcess::Run(argv, log, std::chrono::minutes(5), out);
  EXPECT_TRUE(rc.ok()) << rc.status();
  return rc.ok() ? *rc : -1;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(GestureCli, SweepPrintsTable42Rows) {
  kinemo::testing::TempDir dir;
  std::string out;
  ASSERT_EQ(RunCli({kKinemo, "gmg", "sweep", "--library", kData + "/planner_gesture", "--json"}, dir.File("log"), &out),
            0)
      << out;
  const Json rows = Json::parse(out);
  ASSERT_EQ(rows.size(), 8u);
  for (const auto& r : rows) {
    for (const char* k : {"st", "size", "bf", "scc_size", "scc_bf"}) EXPECT_TRUE(r.contains(k)) << k;
    EXPECT_LE(r["scc_size"].get<int>(), r["size"].get<int>());
  }
  EXPECT_DOUBLE_EQ(rows[0]["st"].get<double>(), 0.3);
  EXPECT_LE(rows[0]["bf"].get<double>(), rows[7]["bf"].get<double>());
}

TEST(GestureCli, GesturesWritesBvhVisemesAndReport) {
  kinemo::testing::TempDir dir;
  std::string out;
  const int rc = RunCli({kKinemo, "gestures", kData + "/speech/sense_and_sensibility_01_austen_64kb-0920.wav",
                      "--library", kData + "/planner_gesture", "-o", dir.File("out.bvh"), "--visemes",
                      dir.File("v.json"), "--report", dir.File("r.json")},
                     dir.File("log"), &out);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(ReadFile(dir.File("out.bvh")).find("HIERARCHY"), std::string::npos);
  const Json report = Json::parse(ReadFile(dir.File("r.json")));
  ASSERT_GT(report["accents"].size(), 3u);
  int placed = 0;
  for (const auto& a : report["accents"]) {
    EXPECT_TRUE(a.contains("papt_s"));
    EXPECT_TRUE(a.contains("psi"));
    if (a["placed"].get<bool>()) {
      ++placed;
      for (const char* k : {"apex_s", "gsi", "warp", "edge"}) EXPECT_TRUE(a.contains(k)) << k;
      const double ta = a["papt_s"].get<double>() - a["apex_s"].get<double>();
      EXPECT_GE(ta, -0.03 - 1e-9);
      EXPECT_LE(ta, 0.22 + 1e-9);
    } else {
      EXPECT_FALSE(a["reason"].get<std::string>().empty());
    }
  }
  EXPECT_GT(placed, 0);
  const Json v = Json::parse(ReadFile(dir.File("v.json")));
  EXPECT_EQ(v["categories"].size(), 15u);
  EXPECT_GT(v["frames"].size(), 100u);
  // Bad input: exit code 2 and a message naming the option.
  EXPECT_EQ(RunCli({kKinemo, "gestures", kData + "/speech/sense_and_sensibility_01_austen_64kb-0920.wav", "--library",
                 kData + "/planner_gesture", "-o", dir.File("x.bvh"), "--algorithm", "nope"},
                dir.File("log2"), &out),
            2);
  EXPECT_NE(out.find("--algorithm"), std::string::npos) << out;
}

}  // namespace
