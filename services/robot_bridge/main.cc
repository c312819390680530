// robot_bridge: serves RobotBridgeService for the robots in its options file.
//
//   robot_bridge --config robot_bridge.textproto [--host H] [--port P] [--port-file F]
#include "common/server/service_host.h"
#include "kinemo/robot_bridge/v1/options.pb.h"
#include "services/robot_bridge/robot_bridge_service.h"

int main(int argc, char** argv) {
  kinemo::robot_bridge::v1::RobotBridgeOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "robot_bridge", &options,
      [](const google::protobuf::Message& message)
          -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        const auto& o = static_cast<const kinemo::robot_bridge::v1::RobotBridgeOptions&>(message);
        KINEMO_ASSIGN_OR_RETURN(auto service,
                                kinemo::robot_bridge::RobotBridgeServiceImpl::Create(o));
        return std::vector<kinemo::server::HostedService>{
            {service, kinemo::robot_bridge::v1::RobotBridgeService::service_full_name()}};
      });
}
