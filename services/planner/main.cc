// The planner server: `planner --config planner.textproto [--port N]`.
#include "common/server/service_host.h"
#include "kinemo/planner/v1/options.pb.h"
#include "services/planner/rpc/planner_service.h"

int main(int argc, char** argv) {
  kinemo::planner::v1::PlannerOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "planner", &options,
      [](const google::protobuf::Message& message)
          -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        const auto& o = static_cast<const kinemo::planner::v1::PlannerOptions&>(message);
        KINEMO_ASSIGN_OR_RETURN(auto svc, kinemo::planner::PlannerServiceImpl::Create(o));
        return std::vector<kinemo::server::HostedService>{
            {svc, kinemo::planner::v1::PlannerService::service_full_name()}};
      });
}
