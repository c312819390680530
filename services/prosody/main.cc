// The prosody server: `prosody [--config prosody.textproto] [--port N]`.
#include <memory>

#include "common/server/service_host.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "services/prosody/prosody_service.h"

int main(int argc, char** argv) {
  kinemo::prosody::v1::ProsodyOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "prosody", &options,
      [](const google::protobuf::Message& loaded)
          -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        const auto& o = static_cast<const kinemo::prosody::v1::ProsodyOptions&>(loaded);
        auto service = std::make_shared<kinemo::prosody::ProsodyServiceImpl>(o);
        return std::vector<kinemo::server::HostedService>{
            {service, kinemo::prosody::v1::ProsodyService::service_full_name()}};
      });
}
