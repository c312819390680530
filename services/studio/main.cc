// studio: the web page a person uses (3D skeleton with audio, timelines,
// live microphone, Vleo-Pleo panel), an HTTP + WebSocket server in front of
// the coordinator.
//
//   studio --config studio.textproto [--host H] [--port P] [--port-file F]
//
// Exit codes: 0 after a clean shutdown (SIGTERM/SIGINT), 2 for bad flags or
// options, 1 when it cannot start (e.g. the port is taken).
#include <filesystem>
#include <iostream>

#include "common/config/options.h"
#include "common/logging/log.h"
#include "common/server/service_host.h"
#include "kinemo/studio/v1/options.pb.h"
#include "services/studio/bridge.h"
#include "services/studio/core/http_server.h"
#include "services/studio/core/options.h"
#include "services/studio/core/routes.h"

#ifndef KINEMO_SOURCE_DIR
#define KINEMO_SOURCE_DIR ""
#endif

int main(int argc, char** argv) {
  namespace ks = kinemo::studio;
  kinemo::server::BlockTerminationSignals();  // before any thread starts
  auto command_line = kinemo::config::ParseServerCommandLine(argc, argv, "studio");
  if (!command_line.ok()) {
    std::cerr << "studio: " << command_line.status().message() << "\n";
    return 2;
  }
  if (command_line->help) {
    std::cout << command_line->usage;
    return 0;
  }
  ks::v1::StudioOptions options;
  ks::SetStudioDefaults(&options);
  kinemo::Status loaded = kinemo::config::LoadServiceOptions(*command_line, &options);
  std::error_code ec;
  const std::string self = std::filesystem::read_symlink("/proc/self/exe", ec).string();
  // No token configured: ResolveStudioOptions makes one (loopback only),
  // which the "listening" line then shows in its URL.
  const bool token_generated = options.auth().token().empty() && options.auth().token_file().empty();
  if (loaded.ok()) loaded = ks::ResolveStudioOptions(self, KINEMO_SOURCE_DIR, &options);
  if (!loaded.ok()) {
    std::cerr << "studio: " << loaded.message() << "\n";
    return 2;
  }
  kinemo::log::Configure(*kinemo::log::ParseLevel(options.server().log_level()),
                         *kinemo::log::ParseFormat(options.server().log_format()), "studio");

  auto bridge = ks::CoordinatorBridge::Create(options);
  if (!bridge.ok()) {
    std::cerr << "studio: " << bridge.status().message() << "\n";
    return 2;
  }
  auto router = std::make_shared<const ks::Router>(options);
  std::shared_ptr<ks::CoordinatorBridge> b = *bridge;
  auto server = ks::HttpServer::Start(
      options, router, [b](std::shared_ptr<ks::SocketConnection> c) { return b->NewHandler(std::move(c)); },
      [b] { return b->HealthJson(); });
  if (!server.ok()) {
    kinemo::log::Error("start_failed", {{"error", std::string(server.status().message())}});
    return server.status().code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
  }
  if (!command_line->port_file.empty()) {
    if (kinemo::Status s = kinemo::config::WriteFileAtomically(command_line->port_file,
                                                               kinemo::StrCat((*server)->port(), "\n"));
        !s.ok()) {
      kinemo::log::Error("start_failed", {{"error", std::string(s.message())}});
      return 1;
    }
  }
  kinemo::log::Info("listening", {{"address", (*server)->address()},
                                  {"port", (*server)->port()},
                                  {"url", (options.server().tls().cert_file().empty() ? "http://" : "https://") +
                                              (*server)->address() + "/" +
                                              (token_generated ? "?token=" + options.auth().token() : "")},
                                  {"coordinator", options.coordinator().address()},
                                  {"static_dir", options.static_dir()},
                                  {"samples", static_cast<int>(router->samples().size())}});
  const int sig = kinemo::server::WaitForTerminationSignal();
  const double grace_s = options.server().shutdown_grace_s() > 0 ? options.server().shutdown_grace_s() : 5;
  kinemo::log::Info("shutting_down", {{"signal", sig}, {"grace_s", grace_s}});
  (*server)->Shutdown(grace_s);
  b->Shutdown(grace_s);
  server->reset();
  kinemo::log::Info("stopped");
  return 0;
}
