// Real processes on loopback for the Vleo -> Pleo tests: one pleo_sim (a
// Modbus-simulated Pleo) per robot, a robot_bridge with every robot, and a
// coordinator (with a store_dir when asked), each restartable on its own.
#pragma once

#include <signal.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/testing/process.h"
#include "gtest/gtest.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"

namespace kinemo::coordinator::vleo_test {

namespace v1 = ::kinemo::coordinator::v1;
namespace rb = ::kinemo::robot_bridge::v1;
using kinemo::testing::ChildProcess;
using kinemo::testing::ServiceProcess;
using namespace std::chrono_literals;

inline const std::string kBin = KINEMO_BINARY_DIR;

using kinemo::testing::WaitForPortFile;

struct Stack {
  struct Robot {
    std::string id;
    std::unique_ptr<ChildProcess> sim;
    int port = 0;
  };
  kinemo::testing::TempDir dir;
  std::vector<Robot> robots;
  std::unique_ptr<ChildProcess> bridge;
  int bridge_port = 0;
  std::unique_ptr<ServiceProcess> coordinator;
  std::unique_ptr<v1::CoordinatorService::Stub> stub;
  std::unique_ptr<rb::RobotBridgeService::Stub> bridge_stub;
  // Coordinator options: the session store ("" = none) and the emotion rate.
  std::string store_dir;
  double rate_per_s = 1.0;  // angry -> happy in 1.5 s

  explicit Stack(std::vector<std::string> robot_ids = {"pleo"}) {
    for (auto& id : robot_ids) robots.push_back({std::move(id), nullptr, 0});
  }

  void StartSim(std::size_t i = 0) {
    Robot& r = robots[i];
    const std::string pf = dir.File(r.id + ".sim.port");
    std::remove(pf.c_str());
    auto s = ChildProcess::Spawn({kBin + "/services/pleo_sim/pleo_sim", "--tcp",
                                  "127.0.0.1:" + std::to_string(r.port), "--port-file", pf,
                                  "--switch-ms", "100"},
                                 dir.File(r.id + ".sim.log"));
    ASSERT_TRUE(s.ok()) << s.status();
    r.sim = std::move(*s);
    r.port = WaitForPortFile(pf, r.sim.get());
    ASSERT_GT(r.port, 0) << r.sim->ReadLog();
  }
  void StartBridge() {
    const std::string cfg = dir.File("rb.textproto"), pf = dir.File("rb.port");
    std::remove(pf.c_str());
    {
      std::ofstream out(cfg);
      out << "server { shutdown_grace_s: 0.5 }\n";
      for (const Robot& r : robots) {
        out << "robots { robot_id: \"" << r.id << "\" tcp { host: \"127.0.0.1\" port: " << r.port
            << " } timing { poll_s: 0.05 max_backoff_s: 0.2 } }\n";
      }
    }
    auto b = ChildProcess::Spawn({kBin + "/services/robot_bridge/robot_bridge", "--config", cfg,
                                  "--host", "127.0.0.1", "--port", std::to_string(bridge_port),
                                  "--port-file", pf},
                                 dir.File("rb.log"));
    ASSERT_TRUE(b.ok()) << b.status();
    bridge = std::move(*b);
    bridge_port = WaitForPortFile(pf, bridge.get());
    ASSERT_GT(bridge_port, 0) << bridge->ReadLog();
    auto channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(bridge_port),
                                       grpc::InsecureChannelCredentials());
    ASSERT_TRUE(kinemo::testing::WaitForServing(channel, "", 20s).ok());
    bridge_stub = rb::RobotBridgeService::NewStub(channel);
  }
  // The coordinator's options file.
  std::string CoordinatorConfig() {
    const std::string cfg = dir.File("coordinator.textproto");
    std::ofstream out(cfg);
    out << "server { shutdown_grace_s: 0.5 }\n"
        << "services { robot_bridge { address: \"127.0.0.1:" << bridge_port
        << "\" max_reconnect_backoff_s: 0.2 } }\n"
        << "emotion { rate_per_s: " << rate_per_s << " }\n"
        << "resend_s: 0.3\n";
    if (!store_dir.empty()) out << "store_dir: \"" << store_dir << "\"\n";
    return cfg;
  }
  void StartCoordinator() {
    auto c = ServiceProcess::Start({.binary = kBin + "/services/coordinator/coordinator",
                                    .args = {"--config", CoordinatorConfig()},
                                    .health_service = v1::CoordinatorService::service_full_name()});
    ASSERT_TRUE(c.ok()) << c.status();
    coordinator = std::move(*c);
    stub = v1::CoordinatorService::NewStub(coordinator->Channel());
  }
  void Start() {
    for (std::size_t i = 0; i < robots.size(); ++i) ASSERT_NO_FATAL_FAILURE(StartSim(i));
    ASSERT_NO_FATAL_FAILURE(StartBridge());
    ASSERT_NO_FATAL_FAILURE(StartCoordinator());
  }

  grpc::Status Open(const std::string& id, common::v1::Emotion initial,
                    const std::string& robot = "pleo") {
    v1::OpenSessionRequest r;
    r.set_session_id(id);
    r.set_robot_id(robot);
    r.set_initial_emotion(initial);
    v1::OpenSessionResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    return stub->OpenSession(&ctx, r, &resp);
  }
  grpc::Status Close(const std::string& id, bool reset_robot) {
    v1::CloseSessionRequest r;
    r.set_session_id(id);
    r.set_reset_robot(reset_robot);
    v1::CloseSessionResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    return stub->CloseSession(&ctx, r, &resp);
  }
  grpc::Status Act(const std::string& id, common::v1::Action action, double intensity,
                   v1::ActResponse* resp = nullptr) {
    v1::ActRequest r;
    r.set_session_id(id);
    r.set_action(action);
    r.set_intensity(intensity);
    v1::ActResponse local;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    return stub->Act(&ctx, r, resp != nullptr ? resp : &local);
  }
  grpc::Status Get(const std::string& id, v1::Session* out) {
    v1::GetSessionRequest g;
    g.set_session_id(id);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    return stub->GetSession(&ctx, g, out);
  }
  // The robot's status as the bridge reads it from pleo_sim's registers.
  bool Status(const std::string& robot, rb::RobotStatus* st) {
    rb::GetStatusRequest r;
    r.set_robot_id(robot);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 1s);
    return bridge_stub->GetStatus(&ctx, r, st).ok();
  }
  // Polls until Pleo shows `e`.
  bool PleoShows(common::v1::Emotion e, std::chrono::milliseconds timeout,
                 const std::string& robot = "pleo") {
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < until) {
      rb::RobotStatus st;
      if (Status(robot, &st) && st.connected() && st.shown_emotion() == e &&
          st.state() == rb::ROBOT_STATE_FOLLOWING) {
        return true;
      }
      std::this_thread::sleep_for(50ms);
    }
    return false;
  }
};

}  // namespace kinemo::coordinator::vleo_test
