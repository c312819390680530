// Relay from sessions to the robot bridge: one worker per robot sends the
// newest emotion with RobotBridgeService.SetEmotion (retrying with backoff
// until it is acknowledged), and one WatchStatus stream per robot reports
// the robot's status to the sessions. Recovery: when the bridge restarts
// (its status shows another commanded emotion, or the stream reconnects)
// or the robot shows another emotion for longer than resend_s, the worker
// re-sends the current emotion. No session waits on the robot. When a
// session closes (a release command), its emotion is no longer re-sent; with
// reset_robot, neutral is sent once (until acknowledged) and not re-sent.
#pragma once

#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <grpcpp/channel.h>
#include <grpcpp/client_context.h>

#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/coordinator/core/clock.h"
#include "services/coordinator/core/session_manager.h"
#include "services/coordinator/idle_watchdog.h"

namespace kinemo::coordinator {

struct RobotRelayOptions {
  double deadline_s = 2.0;        // SetEmotion deadline
  double max_backoff_s = 2.0;     // longest wait between attempts
  double resend_s = 1.0;          // re-send period while the robot disagrees
  // The idle timeout of WatchStatus (deadlines.stream_idle_s): the bridge
  // sends at least every poll period, so a watch silent this long is
  // cancelled and reconnects. Null watchdog = none.
  Watchdog* watchdog = nullptr;
  double stream_idle_s = 0;
};

class RobotRelay {
 public:
  RobotRelay(std::shared_ptr<grpc::Channel> channel, const RobotRelayOptions& options,
             const Clock* clock);
  ~RobotRelay();
  // Set once, before the first Command (the manager is made after the relay).
  void SetManager(SessionManager* manager) { manager_ = manager; }
  // Non-blocking: records the command as the robot's newest.
  void Command(const RobotCommand& command);
  void Stop();

 private:
  struct Worker;
  void CommandLoop(Worker* w);
  void WatchLoop(Worker* w);

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<robot_bridge::v1::RobotBridgeService::Stub> stub_;
  const RobotRelayOptions options_;
  const Clock* clock_;
  SessionManager* manager_ = nullptr;
  std::mutex mu_;
  bool stopping_ = false;
  std::map<std::string, std::unique_ptr<Worker>> workers_;
};

}  // namespace kinemo::coordinator
