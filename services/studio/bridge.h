// The studio's bridge to the coordinator: each WebSocket gets a handler that
// decodes the page's messages (core/messages.h) and runs them as gRPC calls
// on one channel to the coordinator (the stack's front door, which also
// forwards ProsodyService.Analyze): Animate, Analyze, StreamAnimate, the
// session calls, WatchSession. Every call runs on gRPC's callback API (no
// thread per call); its answers go back on the socket with the call's id.
// Closing the socket cancels its calls.
#pragma once

#include <memory>
#include <string>

#include "common/status/status.h"
#include "kinemo/studio/v1/options.pb.h"
#include "services/studio/core/http_server.h"

namespace kinemo::studio {

class CoordinatorBridge {
 public:
  // Opens the channel to options.coordinator() (plaintext, TLS or mutual TLS
  // from its ca_file / cert_file / key_file). INVALID_ARGUMENT naming
  // "coordinator.<field>" for bad TLS material. `options` resolved.
  static StatusOr<std::shared_ptr<CoordinatorBridge>> Create(const v1::StudioOptions& options);
  ~CoordinatorBridge();

  // The handler of a new socket; it greets the page with `hello`.
  std::unique_ptr<SocketHandler> NewHandler(std::shared_ptr<SocketConnection> connection);

  // GET /healthz: {"status":"SERVING","coordinator":ADDRESS,"coordinator_state":STATE}.
  std::string HealthJson() const;

  // Calls running now, over every socket.
  int calls_running() const;

  // Cancels every call still running and waits up to `grace_s` for them to
  // end.
  void Shutdown(double grace_s);

  struct Shared;

 private:
  explicit CoordinatorBridge(std::shared_ptr<Shared> shared);
  std::shared_ptr<Shared> shared_;
};

}  // namespace kinemo::studio
