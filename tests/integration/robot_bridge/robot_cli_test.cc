// `kinemo robot set|status|watch|bench` against real processes: pleo_sim and
// the robot_bridge binary on ephemeral loopback ports.
#include <fstream>

#include "common/testing/process.h"
#include "gtest/gtest.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "nlohmann/json.hpp"
#include "tests/integration/robot_bridge/process_util.h"

namespace kinemo::robot_bridge {
namespace {

using kinemo::testing::ChildProcess;
using kinemo::testing::ServiceProcess;

const std::string kBin = KINEMO_BINARY_DIR;
const std::string kKinemo = kBin + "/services/cli/kinemo";

TEST(RobotCli, SetStatusWatch) {
  kinemo::testing::TempDir dir;
  auto sim = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp", "127.0.0.1:0",
                                  "--port-file", dir.File("sim.port"), "--switch-ms", "50"},
                                 dir.File("sim.log"));
  ASSERT_TRUE(sim.ok()) << sim.status();
  const int port = robot::testing::WaitForPortFile(dir.File("sim.port"));
  ASSERT_GT(port, 0);
  std::ofstream(dir.File("rb.textproto"))
      << "server { shutdown_grace_s: 0.5 }\nrobots { robot_id: \"pleo\" tcp { port: " << port
      << " } }\n";
  auto bridge = ServiceProcess::Start(
      {.binary = kBin + "/services/robot_bridge/robot_bridge",
       .args = {"--config", dir.File("rb.textproto")},
       .health_service = ::kinemo::robot_bridge::v1::RobotBridgeService::service_full_name()});
  ASSERT_TRUE(bridge.ok()) << bridge.status();
  const std::string addr = " --bridge " + (*bridge)->address();

  int rc = -1;
  std::string out =
      robot::testing::Run(kKinemo + " robot set pleo happy --intensity 0.8 --wait" + addr, &rc);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("pleo: happy (0.80)"), std::string::npos) << out;
  EXPECT_NE(out.find("shown"), std::string::npos) << out;

  out = robot::testing::Run(kKinemo + " robot status pleo --json" + addr, &rc);
  ASSERT_EQ(rc, 0) << out;
  auto j = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_EQ(j["shown_emotion"], "EMOTION_HAPPY");
  EXPECT_EQ(j["connected"], true);

  out = robot::testing::Run(kKinemo + " robot status" + addr, &rc);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("pleo: connected"), std::string::npos) << out;

  out = robot::testing::Run(kKinemo + " robot watch pleo -n 2 --json" + addr, &rc);
  ASSERT_EQ(rc, 0) << out;
  int lines = 0;
  for (char c : out) lines += c == '\n';
  EXPECT_GE(lines, 2) << out;

  out = robot::testing::Run(kKinemo + " robot set nobody happy" + addr, &rc);
  EXPECT_EQ(rc, 1);
  EXPECT_NE(out.find("NOT_FOUND"), std::string::npos) << out;
  out = robot::testing::Run(kKinemo + " robot set pleo joyful" + addr, &rc);
  EXPECT_EQ(rc, 2) << out;
  out = robot::testing::Run(kKinemo + " robot set pleo happy --intensity 3" + addr, &rc);
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("INVALID_ARGUMENT"), std::string::npos) << out;
}

TEST(RobotCli, BenchPrintsTheFourFigures) {
  int rc = -1;
  std::string out = robot::testing::Run(
      kKinemo + " robot bench --json --commands 50 --rtu-commands 20 2>/dev/null", &rc);
  ASSERT_EQ(rc, 0) << out;
  auto j = nlohmann::json::parse(out.substr(out.find('{')));
  for (const char* key : {"tcp_p50_ms", "tcp_p99_ms", "rtu_p99_ms", "commands_per_s"}) {
    ASSERT_TRUE(j.contains(key)) << key << " in " << out;
    EXPECT_TRUE(j[key].is_number()) << key << " in " << out;
    EXPECT_GT(j[key].get<double>(), 0) << key;
  }
}

}  // namespace
}  // namespace kinemo::robot_bridge
