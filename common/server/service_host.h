// Server bootstrap shared by every kinemo service.
//
// ServiceHost starts a gRPC server from ServerOptions: TCP host:port (port 0 =
// ephemeral; the bound port is reported) or a unix: socket, the standard
// health service (grpc.health.v1) and server reflection (grpc.reflection.v1
// and v1alpha, see reflection_v1.h), message-size limits,
// optional TLS / mutual TLS, one answer for malformed requests on every RPC
// (INVALID_ARGUMENT naming the field, request_guard.h), and a graceful shutdown that first reports
// NOT_SERVING, then lets calls in flight finish within the grace period.
//
// Every server counts its RPCs (rpc_metrics.h); with server.metrics enabled
// the process serves them as Prometheus' GET /metrics.
//
// ServiceMain() is what a service's main.cc calls: parse flags, load options,
// configure logging, start, start /metrics, write --port-file, wait for
// SIGTERM/SIGINT, stop.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <grpcpp/channel.h>
#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server.h>
#include <grpcpp/support/channel_arguments.h>

#include "common/config/options.h"
#include "common/metrics/metrics.h"
#include "common/status/status.h"
#include "kinemo/common/v1/server.pb.h"

namespace kinemo::server {

// A service to host and its full protobuf name (e.g. Prosody::service_full_name()),
// under which its health status is reported. Or, instead of `service`, the
// server's one generic service (`generic`): it receives every call for a
// method no other service registers (e.g. the coordinator's forwarder);
// `full_name` is then empty.
struct HostedService {
  std::shared_ptr<grpc::Service> service;
  std::string full_name;
  std::shared_ptr<grpc::CallbackGenericService> generic = nullptr;
};

class ServiceHost {
 public:
  // Starts serving `services` (shared: the host keeps them alive while it
  // runs). `name` is used in logs. UNAVAILABLE if the address cannot be bound.
  static StatusOr<std::unique_ptr<ServiceHost>> Start(const common::v1::ServerOptions& options,
                                                      std::string_view name,
                                                      std::vector<HostedService> services);
  // A server without any listening port, reached only through
  // InProcessChannel() (e.g. a service that another one in the same process
  // fronts). address() is empty and port() 0.
  static StatusOr<std::unique_ptr<ServiceHost>> StartInProcess(std::string_view name,
                                                               std::vector<HostedService> services,
                                                               std::uint32_t max_message_bytes);
  ~ServiceHost();
  ServiceHost(const ServiceHost&) = delete;
  ServiceHost& operator=(const ServiceHost&) = delete;

  // "127.0.0.1:40123" or "unix:/path". Ready for clients when Start returns.
  const std::string& address() const { return address_; }
  // The bound TCP port (0 for unix sockets).
  int port() const { return port_; }
  // A channel to this server that bypasses the network (for in-process use).
  std::shared_ptr<grpc::Channel> InProcessChannel(const grpc::ChannelArguments& args = {});
  // Reports `full_name` SERVING (or NOT_SERVING) on grpc.health.v1, e.g.
  // for a service this server reaches through its generic service.
  void SetServing(const std::string& full_name, bool serving);
  // Marks every service NOT_SERVING, then shuts down, cancelling calls still
  // running after the grace period. Idempotent.
  void Shutdown();
  // Blocks until the server has shut down.
  void Wait();
  grpc::Server* grpc_server() { return server_.get(); }

 private:
  ServiceHost() = default;
  // Registers `services` and starts; `listen` empty = in process only.
  static StatusOr<std::unique_ptr<ServiceHost>> Build(
      const common::v1::ServerOptions& options, std::string_view name, std::vector<HostedService> services,
      const std::string& listen, const std::shared_ptr<grpc::ServerCredentials>& credentials);
  std::vector<HostedService> services_;  // declared first: outlives server_
  std::unique_ptr<grpc::Server> server_;
  std::string name_;
  std::string address_;
  int port_ = 0;
  double grace_s_ = 5.0;
  bool shut_down_ = false;
};

// Channel arguments with the same message limit as the server (clients call
// each other with large BVH / audio payloads).
grpc::ChannelArguments ChannelArgsForMessageLimit(std::uint32_t max_message_bytes);

// Blocks SIGINT and SIGTERM in this thread and in threads created after it,
// so that WaitForTerminationSignal() can receive them. Call first in main().
void BlockTerminationSignals();
// Waits for SIGINT or SIGTERM (blocked beforehand); returns the signal number.
int WaitForTerminationSignal();

// Runs a server until SIGINT/SIGTERM. `make_services` runs after the options
// are loaded and validated. Exit codes: 0 after a clean shutdown, 2 for bad
// flags or options, 1 when the server cannot start.
using ServiceFactory =
    std::function<StatusOr<std::vector<HostedService>>(const google::protobuf::Message& options)>;
int ServiceMain(int argc, char** argv, std::string_view name, google::protobuf::Message* options,
                const ServiceFactory& make_services);

// The process' GET /metrics endpoint when options.metrics.enabled (else
// null): logs "metrics_listening" and writes --metrics-port-file. Every
// server of the process is counted there (rpc_metrics.h).
StatusOr<std::unique_ptr<metrics::MetricsEndpoint>> StartMetricsEndpoint(
    const common::v1::ServerOptions& options, const config::ServerCommandLine& command_line);

}  // namespace kinemo::server
