// An in-process pleo_sim (the real libmodbus server and firmware model) on a
// loopback TCP port chosen by the OS, for tests of the bridge core.
#pragma once

#include <chrono>
#include <memory>
#include <thread>

#include "gtest/gtest.h"
#include "services/pleo_sim/server.h"
#include "services/robot_bridge/core/robot_client.h"

namespace kinemo::robot::testing {

class InProcessSim {
 public:
  explicit InProcessSim(pleo_sim::ServerOptions options = Defaults()) {
    options.tcp = true;
    options.host = "127.0.0.1";
    options.port = 0;
    server_ = std::make_unique<pleo_sim::PleoSimServer>(options);
    Status s = server_->Open();
    EXPECT_TRUE(s.ok()) << s;
    port_ = server_->port();
    thread_ = std::thread([this] { run_status_ = server_->Run(); });
  }
  ~InProcessSim() {
    server_->Stop();
    thread_.join();
  }

  static pleo_sim::ServerOptions Defaults() {
    pleo_sim::ServerOptions o;
    o.firmware.switch_ms = 50;
    return o;
  }

  int port() const { return port_; }

  RobotConfig Config(std::string name = "pleo") const {
    RobotConfig c;
    c.name = std::move(name);
    c.link.endpoint.kind = Endpoint::Kind::kTcp;
    c.link.endpoint.host = "127.0.0.1";
    c.link.endpoint.port = port_;
    c.link.response_timeout_ms = 300;
    c.heartbeat_interval_ms = 100;
    c.watchdog_ms = 1000;
    return c;
  }

 private:
  std::unique_ptr<pleo_sim::PleoSimServer> server_;
  std::thread thread_;
  Status run_status_;
  int port_ = 0;
};

// Polls `pred` until it is true or `timeout` passes. Synchronisation by
// condition, never by a fixed sleep.
template <typename Pred>
bool WaitFor(Pred pred, std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return pred();
}

}  // namespace kinemo::robot::testing
