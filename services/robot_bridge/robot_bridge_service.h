// gRPC adapter of the robot bridge (callback API). All robot logic lives in
// core/ (RobotBridge, RobotClient); this file converts protos, maps errors
// with common/grpc, and moves blocking Modbus work off gRPC's threads.
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/metrics/metrics.h"
#include "common/status/status.h"
#include "kinemo/robot_bridge/v1/options.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/robot_bridge/core/robot_bridge.h"

namespace kinemo::robot_bridge {

namespace v1 = ::kinemo::robot_bridge::v1;

// Options → per-robot core configs, with defaults applied and validated.
// Errors name the field ("robots[1].rtu.device: empty").
StatusOr<std::vector<robot::RobotConfig>> ToCoreConfigs(const v1::RobotBridgeOptions& options);

// Core status → API status.
v1::RobotStatus ToProto(const robot::RobotStatus& status);

// API emotion ↔ register value. nullopt for EMOTION_UNSPECIFIED / unknown.
std::optional<int> EmotionToRegister(int api_emotion);
int EmotionFromRegister(robot::Emotion e);

// A few threads for blocking Modbus calls.
class WorkQueue {
 public:
  explicit WorkQueue(int threads);
  ~WorkQueue();
  void Post(std::function<void()> fn);

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> queue_;
  bool stop_ = false;
  std::vector<std::thread> threads_;
};

class RobotBridgeServiceImpl final : public v1::RobotBridgeService::CallbackService {
 public:
  // Validates options, builds the bridge and starts every robot's heartbeat.
  static StatusOr<std::shared_ptr<RobotBridgeServiceImpl>> Create(
      const v1::RobotBridgeOptions& options);
  // Takes a built bridge (tests inject links); starts it.
  RobotBridgeServiceImpl(std::unique_ptr<robot::RobotBridge> bridge, double watch_min_interval_s,
                         int max_watchers);
  ~RobotBridgeServiceImpl() override;

  robot::RobotBridge& bridge() { return *bridge_; }

  grpc::ServerUnaryReactor* SetEmotion(grpc::CallbackServerContext* context,
                                       const v1::SetEmotionRequest* request,
                                       v1::SetEmotionResponse* response) override;
  grpc::ServerUnaryReactor* GetStatus(grpc::CallbackServerContext* context,
                                      const v1::GetStatusRequest* request,
                                      v1::RobotStatus* response) override;
  grpc::ServerWriteReactor<v1::RobotStatus>* WatchStatus(
      grpc::CallbackServerContext* context, const v1::WatchStatusRequest* request) override;
  grpc::ServerUnaryReactor* ListRobots(grpc::CallbackServerContext* context,
                                       const v1::ListRobotsRequest* request,
                                       v1::ListRobotsResponse* response) override;

 private:
  class Watcher;

  std::unique_ptr<robot::RobotBridge> bridge_;
  double watch_min_interval_s_;
  int max_watchers_;
  std::atomic<int> watchers_{0};
  WorkQueue work_;
  // Robot link metrics, read from each robot's cached status when scraped;
  // declared last: gone before the bridge.
  std::vector<std::unique_ptr<metrics::ScrapeRegistration>> metrics_;
};

}  // namespace kinemo::robot_bridge
