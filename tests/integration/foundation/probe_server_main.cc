// A server made of the bootstrap alone (health + reflection, no service of
// its own): the test peer for the integration harness and ServiceMain.
#include "common/server/service_host.h"

int main(int argc, char** argv) {
  kinemo::common::v1::ServerOptions options;
  return kinemo::server::ServiceMain(
      argc, argv, "probe", &options,
      [](const google::protobuf::Message&) -> kinemo::StatusOr<std::vector<kinemo::server::HostedService>> {
        return std::vector<kinemo::server::HostedService>{};
      });
}
