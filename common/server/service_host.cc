#include "common/server/service_host.h"

#include <signal.h>

#include <chrono>
#include <cstdio>
#include <iostream>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_builder.h>

#include "absl/strings/str_cat.h"
#include "common/grpc/runtime.h"
#include "common/grpc/tls_credentials.h"
#include "common/logging/log.h"
#include "common/metrics/metrics.h"
#include "common/server/reflection_v1.h"
#include "common/server/request_guard.h"
#include "common/server/rpc_metrics.h"

namespace kinemo::server {
namespace {

bool IsUnix(const std::string& host) { return host.rfind("unix:", 0) == 0; }

std::string FormatHostPort(const std::string& host, int port) {
  // Bare IPv6 literals need brackets.
  if (host.find(':') != std::string::npos && host.front() != '[') {
    return kinemo::StrCat("[", host, "]:", port);
  }
  return kinemo::StrCat(host, ":", port);
}

}  // namespace

StatusOr<std::unique_ptr<ServiceHost>> ServiceHost::Start(
    const common::v1::ServerOptions& options_in, std::string_view name,
    std::vector<HostedService> services) {
  common::v1::ServerOptions options = options_in;
  config::ApplyServerDefaults(&options);
  KINEMO_RETURN_IF_ERROR(config::ValidateServerOptions(options));
  KINEMO_ASSIGN_OR_RETURN(auto credentials, MakeServerCredentials(options.tls()));
  const std::string listen = IsUnix(options.host())
                                 ? options.host()
                                 : FormatHostPort(options.host(), static_cast<int>(options.port()));
  return Build(options, name, std::move(services), listen, credentials);
}

StatusOr<std::unique_ptr<ServiceHost>> ServiceHost::StartInProcess(std::string_view name,
                                                                   std::vector<HostedService> services,
                                                                   std::uint32_t max_message_bytes) {
  common::v1::ServerOptions options;
  options.set_max_message_bytes(max_message_bytes);
  config::ApplyServerDefaults(&options);
  return Build(options, name, std::move(services), "", nullptr);
}

StatusOr<std::unique_ptr<ServiceHost>> ServiceHost::Build(
    const common::v1::ServerOptions& options, std::string_view name, std::vector<HostedService> services,
    const std::string& listen, const std::shared_ptr<grpc::ServerCredentials>& credentials) {
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  UseReleaseLockChecks();

  auto host = std::unique_ptr<ServiceHost>(new ServiceHost());
  host->name_ = std::string(name);
  host->grace_s_ = options.shutdown_grace_s();

  // grpc.reflection.v1 beside the plugin's v1alpha, relayed to it.
  auto reflection_v1 = std::make_shared<ReflectionV1Service>();
  services.push_back({reflection_v1, ""});

  grpc::ServerBuilder builder;
  int bound_port = 0;
  const bool unix_socket = IsUnix(listen);
  if (!listen.empty()) builder.AddListeningPort(listen, credentials, unix_socket ? nullptr : &bound_port);
  // gRPC sets SO_REUSEPORT by default: a second server on the same port would
  // silently share its traffic. A port clash must be an error instead.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.SetMaxReceiveMessageSize(static_cast<int>(options.max_message_bytes()));
  builder.SetMaxSendMessageSize(static_cast<int>(options.max_message_bytes()));
  bool have_generic = false;
  for (const HostedService& hosted : services) {
    if (hosted.generic != nullptr) {
      if (have_generic || hosted.service != nullptr) {
        return absl::InternalError("ServiceHost: one generic service per server, given alone");
      }
      have_generic = true;
      builder.RegisterCallbackGenericService(hosted.generic.get());
      continue;
    }
    if (hosted.service == nullptr) return absl::InternalError("ServiceHost: null service");
    GuardRequests(hosted.service.get());
    builder.RegisterService(hosted.service.get());
  }
  // Malformed requests get INVALID_ARGUMENT naming the field (request_guard.h);
  // then RPC counts, latencies and calls in flight (rpc_metrics.h), whether or
  // not this process serves /metrics. Send hooks run in this order, so the
  // metrics count the status the guard rewrote.
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(MakeRequestGuardFactory());
  interceptors.push_back(MakeRpcMetricsInterceptorFactory());
  builder.experimental().SetInterceptorCreators(std::move(interceptors));
  host->server_ = builder.BuildAndStart();
  if (host->server_ == nullptr || (!listen.empty() && !unix_socket && bound_port == 0)) {
    return absl::UnavailableError(kinemo::StrCat("server.host/server.port: cannot listen on ", listen,
                                               " (address in use or not local?)"));
  }
  reflection_v1->SetBackend(
      host->server_->InProcessChannel(ChannelArgsForMessageLimit(options.max_message_bytes())));
  host->port_ = unix_socket ? 0 : bound_port;
  host->address_ = listen.empty() || unix_socket ? listen : FormatHostPort(options.host(), bound_port);

  // Health: the server as a whole ("") and each service by its full name.
  auto* health = host->server_->GetHealthCheckService();
  if (health != nullptr) {
    health->SetServingStatus(true);
    for (const HostedService& hosted : services) {
      if (!hosted.full_name.empty()) health->SetServingStatus(hosted.full_name, true);
    }
  }
  host->services_ = std::move(services);
  return host;
}

void ServiceHost::SetServing(const std::string& full_name, bool serving) {
  if (server_ == nullptr || shut_down_) return;
  if (auto* health = server_->GetHealthCheckService()) health->SetServingStatus(full_name, serving);
}

ServiceHost::~ServiceHost() { Shutdown(); }

std::shared_ptr<grpc::Channel> ServiceHost::InProcessChannel(const grpc::ChannelArguments& args) {
  return server_->InProcessChannel(args);
}

void ServiceHost::Shutdown() {
  if (shut_down_ || server_ == nullptr) return;
  shut_down_ = true;
  if (auto* health = server_->GetHealthCheckService()) {
    health->SetServingStatus(false);
  }
  const auto deadline =
      std::chrono::system_clock::now() +
      std::chrono::milliseconds(static_cast<long>(grace_s_ * 1000.0));
  server_->Shutdown(deadline);
  server_->Wait();
}

void ServiceHost::Wait() {
  if (server_ != nullptr) server_->Wait();
}

grpc::ChannelArguments ChannelArgsForMessageLimit(std::uint32_t max_message_bytes) {
  grpc::ChannelArguments args;
  const int limit = max_message_bytes == 0 ? (16 << 20) : static_cast<int>(max_message_bytes);
  args.SetMaxReceiveMessageSize(limit);
  args.SetMaxSendMessageSize(limit);
  return args;
}

void BlockTerminationSignals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
}

int WaitForTerminationSignal() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  int sig = 0;
  while (sigwait(&set, &sig) != 0) {
  }
  return sig;
}

int ServiceMain(int argc, char** argv, std::string_view name, google::protobuf::Message* options,
                const ServiceFactory& make_services) {
  BlockTerminationSignals();  // before gRPC creates any thread
  auto command_line = config::ParseServerCommandLine(argc, argv, name);
  if (!command_line.ok()) {
    std::cerr << name << ": " << command_line.status().message() << "\n";
    return 2;
  }
  if (command_line->help) {
    std::cout << command_line->usage;
    return 0;
  }
  if (Status s = config::LoadServiceOptions(*command_line, options); !s.ok()) {
    std::cerr << name << ": " << s.message() << "\n";
    return 2;
  }
  const common::v1::ServerOptions& server_options = *config::MutableServerOptions(options);
  log::Configure(*log::ParseLevel(server_options.log_level()),
                 *log::ParseFormat(server_options.log_format()), name);

  RedactOptionPaths(*options);  // no configured root in the messages clients get
  auto services = make_services(*options);
  if (!services.ok()) {
    log::Error("start_failed", {{"error", std::string(services.status().message())}});
    return services.status().code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
  }
  auto host = ServiceHost::Start(server_options, name, std::move(*services));
  if (!host.ok()) {
    log::Error("start_failed", {{"error", std::string(host.status().message())}});
    return 1;
  }
  auto metrics = StartMetricsEndpoint(server_options, *command_line);
  if (!metrics.ok()) {
    log::Error("start_failed", {{"error", std::string(metrics.status().message())}});
    return 1;
  }
  if (!command_line->port_file.empty()) {
    if (Status s = config::WriteFileAtomically(command_line->port_file,
                                               kinemo::StrCat((*host)->port(), "\n"));
        !s.ok()) {
      log::Error("start_failed", {{"error", std::string(s.message())}});
      return 1;
    }
  }
  log::Info("listening", {{"address", (*host)->address()}, {"port", (*host)->port()},
                          {"tls", server_options.has_tls() && !server_options.tls().cert_file().empty()}});
  const int sig = WaitForTerminationSignal();
  log::Info("shutting_down", {{"signal", sig}, {"grace_s", server_options.shutdown_grace_s()}});
  (*host)->Shutdown();
  host->reset();
  metrics->reset();
  log::Info("stopped");
  return 0;
}

StatusOr<std::unique_ptr<metrics::MetricsEndpoint>> StartMetricsEndpoint(
    const common::v1::ServerOptions& options, const config::ServerCommandLine& command_line) {
  if (!options.metrics().enabled()) return std::unique_ptr<metrics::MetricsEndpoint>();
  KINEMO_ASSIGN_OR_RETURN(auto endpoint, metrics::MetricsEndpoint::Start(options.metrics()));
  if (!command_line.metrics_port_file.empty()) {
    KINEMO_RETURN_IF_ERROR(config::WriteFileAtomically(command_line.metrics_port_file,
                                                       kinemo::StrCat(endpoint->port(), "\n")));
  }
  log::Info("metrics_listening", {{"address", endpoint->address()}, {"port", endpoint->port()}});
  return endpoint;
}

}  // namespace kinemo::server
