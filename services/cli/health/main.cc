// kinemo-health: a readiness probe for containers and scripts.
//   kinemo-health ADDR [--service NAME] [--timeout-s S] [--fail-fast]   grpc.health.v1 Check; exit 0 when SERVING
//   kinemo-health --tcp HOST:PORT [--timeout-s S]                       TCP connect (Modbus pleo_sim)
// It waits up to --timeout-s for the server to come up; with --fail-fast it
// gives up at the first failed connection attempt (nothing listening, a TLS
// handshake refused) and says why. Over TLS / mutual TLS with --ca, --cert,
// --key (or $KINEMO_TLS_CA, $KINEMO_TLS_CERT, $KINEMO_TLS_KEY), as every kinemo
// tool. `--timeout` is the old spelling of --timeout-s (deprecated).
// Exit codes: 0 ready, 1 not ready (message on stderr), 2 usage.
#include <arpa/inet.h>
#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>
#include <grpcpp/grpcpp.h>

#include "grpc/health/v1/health.grpc.pb.h"
#include "services/cli/channel.h"
#include "services/cli/commands.h"

namespace {

int CheckTcp(const std::string& address, double timeout_s) {
  const auto colon = address.rfind(':');
  if (colon == std::string::npos) {
    std::cerr << "kinemo-health: --tcp: expected HOST:PORT, got '" << address << "'\n";
    return 2;
  }
  const std::string host = address.substr(0, colon), port = address.substr(colon + 1);
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (getaddrinfo(host.c_str(), port.c_str(), &hints, &found) != 0 || found == nullptr) {
    std::cerr << "kinemo-health: " << address << ": cannot resolve\n";
    return 1;
  }
  int result = 1;
  for (addrinfo* a = found; a != nullptr && result != 0; a = a->ai_next) {
    const int fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) continue;
    timeval tv{static_cast<time_t>(timeout_s), static_cast<suseconds_t>((timeout_s - static_cast<int>(timeout_s)) * 1e6)};
    setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    if (connect(fd, a->ai_addr, a->ai_addrlen) == 0) result = 0;
    close(fd);
  }
  freeaddrinfo(found);
  if (result != 0) std::cerr << "kinemo-health: " << address << ": connection refused\n";
  return result;
}

int CheckGrpc(const std::string& address, const std::string& service, double timeout_s, bool fail_fast) {
  auto credentials = kinemo::MakeChannelCredentials(kinemo::cli::CliTlsFiles());
  if (!credentials.ok()) {
    std::cerr << "kinemo-health: " << credentials.status().message() << "\n";
    return 2;
  }
  auto channel = grpc::CreateChannel(address, *credentials);
  auto stub = grpc::health::v1::Health::NewStub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(static_cast<long>(timeout_s * 1000)));
  // Waiting for ready rides out a server that is still starting; fail-fast
  // ends the call when the first connection attempt fails.
  ctx.set_wait_for_ready(!fail_fast);
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status = stub->Check(&ctx, request, &response);
  if (!status.ok()) {
    std::cerr << "kinemo-health: " << address << ": " << status.error_message() << "\n";
    return 1;
  }
  if (response.status() != grpc::health::v1::HealthCheckResponse::SERVING) {
    std::cerr << "kinemo-health: " << address << ": "
              << grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response.status()) << "\n";
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"kinemo-health: is a kinemo service ready?", "kinemo-health"};
  std::string address, service, tcp;
  double timeout_s = 2;
  bool fail_fast = false;
  app.add_option("address", address, "gRPC address, e.g. localhost:50051 or unix:/run/kinemo.sock");
  app.add_option("--service", service, "service name to check (empty = the whole server)");
  app.add_option("--tcp", tcp, "check a TCP port instead (HOST:PORT)");
  app.add_option("--timeout-s", timeout_s, "how long to wait for the server, in seconds (0.001 to 3600, default 2)");
  kinemo::cli::AddDeprecatedOption(&app, "--timeout", "--timeout-s", timeout_s, "kinemo-health");
  app.add_flag("--fail-fast", fail_fast,
               "give up at the first failed connection attempt instead of waiting up to --timeout-s (gRPC only)");
  kinemo::cli::AddTlsOptions(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  // Checked here, not by CLI11, so that either spelling's error names the option.
  if (!(timeout_s >= 0.001 && timeout_s <= 3600)) {
    std::cerr << "kinemo-health: --timeout-s: " << timeout_s << " is outside [0.001, 3600] seconds\n";
    return 2;
  }
  if (!tcp.empty()) return CheckTcp(tcp, timeout_s);
  if (address.empty()) {
    std::cerr << "kinemo-health: give a gRPC ADDRESS or --tcp HOST:PORT\n";
    return 2;
  }
  return CheckGrpc(address, service, timeout_s, fail_fast);
}
