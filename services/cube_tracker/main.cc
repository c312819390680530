// cube_tracker: the marker-cube tracker server.
//   cube_tracker --config cube_tracker.textproto [--host H] [--port N] [--port-file F]
#include "common/server/service_host.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "services/cube_tracker/cube_tracker_service.h"

int main(int argc, char** argv) {
  kinemo::cube_tracker::v1::CubeTrackerOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "cube_tracker", &options,
      [](const google::protobuf::Message& loaded) -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        const auto& o = static_cast<const kinemo::cube_tracker::v1::CubeTrackerOptions&>(loaded);
        KINEMO_ASSIGN_OR_RETURN(auto service, kinemo::cube_tracker::CubeTrackerService::Create(o));
        return std::vector<kinemo::server::HostedService>{
            {service, kinemo::cube_tracker::v1::CubeTrackerService::service_full_name()}};
      });
}
