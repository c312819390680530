// coordinator: Vleo-Pleo sessions, the speech -> animation pipeline, and the
// stack's front door (calls for prosody, inference, planner and cube_tracker
// are forwarded to them; see forwarder.h).
//
//   coordinator --config coordinator.textproto [--host H] [--port P] [--port-file F]
#include "common/server/service_host.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "services/coordinator/coordinator_service.h"
#include "services/coordinator/forwarder.h"

int main(int argc, char** argv) {
  kinemo::coordinator::v1::CoordinatorOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "coordinator", &options,
      [](const google::protobuf::Message& message)
          -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        const auto& o = static_cast<const kinemo::coordinator::v1::CoordinatorOptions&>(message);
        KINEMO_ASSIGN_OR_RETURN(auto service, kinemo::coordinator::CoordinatorServiceImpl::Create(o));
        auto forwarder = kinemo::coordinator::Forwarder::ForCoordinator(o, service->channels());
        return std::vector<kinemo::server::HostedService>{
            {service, kinemo::coordinator::v1::CoordinatorService::service_full_name()},
            {.generic = forwarder}};
      });
}
