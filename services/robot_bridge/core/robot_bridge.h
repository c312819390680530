// RobotBridge: the set of robots this bridge drives, by name.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "common/status/status.h"
#include "services/robot_bridge/core/robot_client.h"

namespace kinemo::robot {

class RobotBridge {
 public:
  using LinkFactory = std::function<std::unique_ptr<ModbusLink>(const RobotConfig&)>;

  // Validates every config (unique names) and builds one client per robot.
  // `factory` defaults to libmodbus links.
  static StatusOr<std::unique_ptr<RobotBridge>> Create(std::vector<RobotConfig> robots,
                                                       LinkFactory factory = nullptr);
  ~RobotBridge();

  // Starts / stops every robot's heartbeat.
  void Start();
  void Stop();

  // NOT_FOUND (naming the known robots) for an unknown name.
  StatusOr<RobotClient*> Find(std::string_view name) const;
  // Names in sorted order.
  std::vector<std::string> Names() const;

 private:
  RobotBridge() = default;
  std::map<std::string, std::unique_ptr<RobotClient>, std::less<>> robots_;
};

}  // namespace kinemo::robot
