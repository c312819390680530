// coordinator: Vleo-Pleo sessions and the speech -> animation pipeline.
//
//   coordinator --config coordinator.textproto [--host H] [--port P] [--port-file F]
#include "common/server/service_host.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "services/coordinator/coordinator_service.h"

int main(int argc, char** argv) {
  kinemo::coordinator::v1::CoordinatorOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "coordinator", &options,
      [](const google::protobuf::Message& message)
          -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        const auto& o = static_cast<const kinemo::coordinator::v1::CoordinatorOptions&>(message);
        KINEMO_ASSIGN_OR_RETURN(auto service, kinemo::coordinator::CoordinatorServiceImpl::Create(o));
        return std::vector<kinemo::server::HostedService>{
            {service, kinemo::coordinator::v1::CoordinatorService::service_full_name()}};
      });
}
