// The inference server: `inference --config inference.textproto [--port N]`.
#include "common/server/service_host.h"
#include "kinemo/inference/v1/options.pb.h"
#include "services/inference/inference_service.h"

int main(int argc, char** argv) {
  kinemo::inference::v1::InferenceOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "inference", &options,
      [](const google::protobuf::Message& message)
          -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        const auto& o = static_cast<const kinemo::inference::v1::InferenceOptions&>(message);
        KINEMO_ASSIGN_OR_RETURN(auto svc, kinemo::inference::InferenceServiceImpl::Create(o));
        return std::vector<kinemo::server::HostedService>{
            {svc, kinemo::inference::v1::InferenceService::service_full_name()}};
      });
}
