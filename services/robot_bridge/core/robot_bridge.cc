#include "services/robot_bridge/core/robot_bridge.h"

#include "absl/strings/str_cat.h"
#include "services/robot_bridge/core/errors.h"
#include "absl/strings/str_join.h"

namespace kinemo::robot {

StatusOr<std::unique_ptr<RobotBridge>> RobotBridge::Create(std::vector<RobotConfig> robots,
                                                           LinkFactory factory) {
  std::unique_ptr<RobotBridge> bridge(new RobotBridge());
  for (size_t i = 0; i < robots.size(); ++i) {
    Status s = ValidateRobotConfig(robots[i]);
    if (!s.ok()) return Context(s, absl::StrCat("robots[", i, "]"));
    if (bridge->robots_.count(robots[i].name) != 0) {
      return BadField(absl::StrCat("robots[", i, "].name"), "'", robots[i].name,
                          "' is used twice");
    }
    std::unique_ptr<ModbusLink> link =
        factory ? factory(robots[i]) : NewLibmodbusLink(robots[i].link);
    std::string name = robots[i].name;
    bridge->robots_.emplace(name,
                            std::make_unique<RobotClient>(std::move(robots[i]), std::move(link)));
  }
  return bridge;
}

RobotBridge::~RobotBridge() { Stop(); }

void RobotBridge::Start() {
  for (auto& [name, robot] : robots_) robot->Start();
}

void RobotBridge::Stop() {
  for (auto& [name, robot] : robots_) robot->Stop();
}

StatusOr<RobotClient*> RobotBridge::Find(std::string_view name) const {
  auto it = robots_.find(name);
  if (it == robots_.end()) {
    return absl::NotFoundError(absl::StrCat("robot '", AV(name), "': no such robot (known: ",
                                            robots_.empty() ? "none" : absl::StrJoin(Names(), ", "),
                                            ")"));
  }
  return it->second.get();
}

std::vector<std::string> RobotBridge::Names() const {
  std::vector<std::string> names;
  names.reserve(robots_.size());
  for (const auto& [name, robot] : robots_) names.push_back(name);
  return names;
}

}  // namespace kinemo::robot
