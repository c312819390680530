// The integration harness against a real server binary: ephemeral port,
// readiness by health check, graceful stop on SIGTERM, clear start-up errors.
#include <gtest/gtest.h>
#include <signal.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/testing/process.h"

namespace kinemo::testing {
namespace {

std::string Probe() {
  static const std::string path = FindBuiltBinary(KINEMO_BINARY_DIR, "kinemo_probe_server");
  return path;
}

std::vector<nlohmann::json> JsonLines(const std::string& log) {
  std::vector<nlohmann::json> out;
  std::istringstream in(log);
  std::string line;
  while (std::getline(in, line)) {
    auto j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!j.is_discarded()) out.push_back(j);
  }
  return out;
}

TEST(Harness, StartsOnAnEphemeralPortAndStopsGracefully) {
  ASSERT_FALSE(Probe().empty());
  auto svc = ServiceProcess::Start({.binary = Probe()});
  ASSERT_TRUE(svc.ok()) << svc.status();
  EXPECT_GT((*svc)->port(), 0);
  EXPECT_TRUE((*svc)->process().Running());
  auto code = (*svc)->Stop();
  ASSERT_TRUE(code.ok()) << code.status();
  EXPECT_EQ(*code, 0);
  const auto lines = JsonLines((*svc)->process().ReadLog());
  bool listening = false, stopped = false;
  for (const auto& j : lines) {
    if (j.value("event", "") == "listening") {
      listening = true;
      EXPECT_EQ(j["port"], (*svc)->port());
      EXPECT_EQ(j["component"], "probe");
    }
    if (j.value("event", "") == "stopped") stopped = true;
  }
  EXPECT_TRUE(listening);
  EXPECT_TRUE(stopped);
}

TEST(Harness, TwoInstancesGetDifferentPorts) {
  auto a = ServiceProcess::Start({.binary = Probe()});
  auto b = ServiceProcess::Start({.binary = Probe()});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NE((*a)->port(), (*b)->port());
}

TEST(Harness, SigintAlsoStopsCleanly) {
  auto svc = ServiceProcess::Start({.binary = Probe()});
  ASSERT_TRUE(svc.ok());
  auto code = (*svc)->process().Stop(SIGINT, std::chrono::milliseconds(10000));
  ASSERT_TRUE(code.ok());
  EXPECT_EQ(*code, 0);
}

TEST(Harness, BadOptionsFileFailsFastWithFileAndLine) {
  TempDir dir;
  std::ofstream(dir.File("bad.textproto")) << "host: \"127.0.0.1\"\nport: banana\n";
  auto svc = ServiceProcess::Start({.binary = Probe(), .args = {"--config", dir.File("bad.textproto")}});
  ASSERT_FALSE(svc.ok());
  EXPECT_EQ(svc.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(svc.status().message().find("exited with code 2"), std::string::npos) << svc.status();
  EXPECT_NE(svc.status().message().find("bad.textproto:2:"), std::string::npos) << svc.status();
}

TEST(Harness, PortInUseExitsWithCodeOne) {
  auto first = ServiceProcess::Start({.binary = Probe()});
  ASSERT_TRUE(first.ok());
  TempDir dir;
  auto child = ChildProcess::Spawn(
      {Probe(), "--host", "127.0.0.1", "--port", std::to_string((*first)->port())}, dir.File("log"));
  ASSERT_TRUE(child.ok());
  auto code = (*child)->WaitExit(std::chrono::milliseconds(20000));
  ASSERT_TRUE(code.ok()) << code.status();
  EXPECT_EQ(*code, 1);
  EXPECT_NE((*child)->ReadLog().find("cannot listen"), std::string::npos);
}

TEST(Harness, MissingBinaryIsNotFound) {
  auto svc = ServiceProcess::Start({.binary = "/nonexistent/kinemo_nothing"});
  ASSERT_FALSE(svc.ok());
  EXPECT_EQ(svc.status().code(), absl::StatusCode::kNotFound);
}

TEST(Harness, ChildThatNeverListensTimesOutWithItsLog) {
  // /bin/sleep exits on its own later; it never writes the port file.
  auto svc = ServiceProcess::Start({.binary = "/bin/sleep", .args = {"30"},
                                    .ready_timeout = std::chrono::milliseconds(300)});
  ASSERT_FALSE(svc.ok());
  EXPECT_TRUE(svc.status().code() == absl::StatusCode::kDeadlineExceeded ||
              svc.status().code() == absl::StatusCode::kUnavailable)
      << svc.status();
}

}  // namespace
}  // namespace kinemo::testing
