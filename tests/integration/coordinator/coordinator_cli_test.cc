// The `kinemo session` and `kinemo demo vleo` commands against real
// processes (pleo_sim, robot_bridge, coordinator; the demo starts its own).
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include "common/testing/process.h"
#include "gtest/gtest.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "nlohmann/json.hpp"

namespace kinemo::coordinator {
namespace {

using kinemo::testing::ChildProcess;
using kinemo::testing::ServiceProcess;
using namespace std::chrono_literals;

const std::string kBin = KINEMO_BINARY_DIR;
const std::string kKinemo = kBin + "/services/cli/kinemo";
const std::string kSource = KINEMO_SOURCE_DIR;

// Runs a command; returns its exit code and stdout.
int RunShell(const std::string& command, std::string* out) {
  FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return -1;
  std::array<char, 4096> buf;
  out->clear();
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out->append(buf.data(), n);
  const int st = ::pclose(p);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

int WaitForPortFile(const std::string& path, ChildProcess* child) {
  const auto until = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < until) {
    std::ifstream in(path);
    int port = 0;
    if (in >> port && port > 0) return port;
    if (!child->Running()) return -1;
    std::this_thread::sleep_for(20ms);
  }
  return -1;
}

TEST(CoordinatorCli, SessionOpenActWatchListClose) {
  kinemo::testing::TempDir dir;
  auto sim = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp", "127.0.0.1:0",
                                  "--port-file", dir.File("sim.port"), "--switch-ms", "100"},
                                 dir.File("sim.log"));
  ASSERT_TRUE(sim.ok());
  const int sim_port = WaitForPortFile(dir.File("sim.port"), sim->get());
  ASSERT_GT(sim_port, 0);
  std::ofstream(dir.File("rb.textproto"))
      << "robots { robot_id: \"pleo\" tcp { host: \"127.0.0.1\" port: " << sim_port << " } }\n";
  auto bridge = ServiceProcess::Start({.binary = kBin + "/services/robot_bridge/robot_bridge",
                                       .args = {"--config", dir.File("rb.textproto")}});
  ASSERT_TRUE(bridge.ok()) << bridge.status();
  std::ofstream(dir.File("co.textproto"))
      << "services { robot_bridge { address: \"" << (*bridge)->address() << "\" } }\n"
      << "emotion { rate_per_s: 0.5 }\n";  // neutral after 1.4 s, happy after 3 s
  auto coordinator = ServiceProcess::Start({.binary = kBin + "/services/coordinator/coordinator",
                                            .args = {"--config", dir.File("co.textproto")}});
  ASSERT_TRUE(coordinator.ok()) << coordinator.status();
  const std::string c = " --coordinator " + (*coordinator)->address();
  std::string out;
  ASSERT_EQ(RunShell(kKinemo + " session open pleo --id vleo --initial angry --json" + c, &out), 0);
  auto opened = nlohmann::json::parse(out);
  EXPECT_EQ(opened["session_id"], "vleo");
  EXPECT_EQ(opened["emotion"], "EMOTION_ANGRY");
  ASSERT_EQ(RunShell(kKinemo + " session act vleo kisses -i 1 --json" + c, &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["action"], "ACTION_KISSES");
  // Watch until the robot was commanded happy (snapshot + changes).
  ASSERT_EQ(RunShell(kKinemo + " session watch vleo --json --duration-s 10" + c + " | grep -m1 -B100 "
                "'\"robot_commanded\":{\"emotion\":\"EMOTION_HAPPY\"'",
                &out),
            0)
      << out;
  std::istringstream lines(out);
  std::string line;
  std::vector<std::string> emotions;
  while (std::getline(lines, line)) {
    auto j = nlohmann::json::parse(line);
    if (j.contains("emotion_changed")) emotions.push_back(j["emotion_changed"]["to_emotion"]);
  }
  EXPECT_EQ(emotions, (std::vector<std::string>{"EMOTION_NEUTRAL", "EMOTION_HAPPY"}));
  ASSERT_EQ(RunShell(kKinemo + " session list --json" + c, &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["sessions"].size(), 1u);
  ASSERT_EQ(RunShell(kKinemo + " session close vleo --json" + c, &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["emotion"], "EMOTION_HAPPY");
  EXPECT_EQ(RunShell(kKinemo + " session act vleo kisses" + c + " 2>/dev/null", &out), 1);
  EXPECT_EQ(RunShell(kKinemo + " session act vleo dance" + c + " 2>/dev/null", &out), 2);
}

TEST(CoordinatorCli, DemoVleoPrintsPleosStateChangesAndPleoSimFollows) {
  kinemo::testing::TempDir dir;
  std::string out;
  const int rc = RunShell("cd " + kSource + " && " + kKinemo + " demo vleo --json --out " + dir.path() +
                         " 2>" + dir.File("demo.err"),
                     &out);
  std::ifstream err(dir.File("demo.err"));
  std::stringstream es;
  es << err.rdbuf();
  ASSERT_EQ(rc, 0) << es.str();  // 0: pleo_sim ends in the model's emotion
  std::istringstream lines(out);
  std::string line;
  std::vector<std::string> seq;
  double last_t = 0;
  while (std::getline(lines, line)) {
    auto j = nlohmann::json::parse(line);
    ASSERT_TRUE(j.contains("time_s") && j.contains("action") && j.contains("intensity"));
    EXPECT_GE(j["time_s"].get<double>(), last_t);
    last_t = j["time_s"];
    seq.push_back(j["action"].get<std::string>() + ":" + j["emotion"].get<std::string>());
  }
  // The scripted cube: kisses (turned up to full intensity), then shouting.
  EXPECT_EQ(seq, (std::vector<std::string>{"kisses:neutral", "kisses:happy", "shouting:neutral",
                                           "shouting:angry"}));
}

}  // namespace
}  // namespace kinemo::coordinator
