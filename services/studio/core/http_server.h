// The studio's HTTP + WebSocket server (Boost.Beast on Asio): serves the
// routes of routes.h and hands each WebSocket to a SocketHandler. No gRPC
// here; the bridge to the coordinator is a SocketHandler (bridge.h).
//
// Threads: `io_threads` run every connection; each connection's reads,
// writes and handler calls are serialised on its own strand. A socket's
// outgoing frames are queued; a page that stops reading until more than
// 64 MiB + max_upload_bytes are queued is disconnected.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "common/status/status.h"
#include "kinemo/studio/v1/options.pb.h"
#include "services/studio/core/routes.h"

namespace kinemo::studio {

// An open WebSocket, as its handler (and whatever the handler starts) sees
// it. Thread-safe; does nothing once the socket has closed.
class SocketConnection {
 public:
  virtual ~SocketConnection() = default;
  // Queues one text frame.
  virtual void Send(std::string text) = 0;
  // Closes the socket (normal closure).
  virtual void Close() = 0;
};

// What the studio does with one socket. Calls come one at a time.
class SocketHandler {
 public:
  virtual ~SocketHandler() = default;
  // One text frame from the page.
  virtual void OnText(std::string_view text) = 0;
  // The socket closed (called once; no OnText after it).
  virtual void OnClose() = 0;
};

// Makes the handler of a new socket (called once per socket, before any
// OnText).
using HandlerFactory = std::function<std::unique_ptr<SocketHandler>(std::shared_ptr<SocketConnection>)>;

class HttpServer {
 public:
  // Binds options.server().host():port() (port 0 = ephemeral) and starts
  // serving. `health_body` writes the JSON of GET /healthz. `options` must be
  // resolved (ResolveStudioOptions). UNAVAILABLE if the address cannot be
  // bound, INVALID_ARGUMENT for a host that is not an IP address or "localhost".
  static StatusOr<std::unique_ptr<HttpServer>> Start(const v1::StudioOptions& options,
                                                     std::shared_ptr<const Router> router,
                                                     HandlerFactory make_handler,
                                                     std::function<std::string()> health_body);
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  int port() const;
  // "127.0.0.1:8080".
  std::string address() const;
  // Open WebSockets now.
  int open_sockets() const;
  // Stops accepting, closes every socket ("going away", their handlers'
  // OnClose runs), waits for them up to `grace_s`, then stops the threads.
  // Idempotent.
  void Shutdown(double grace_s);

  class Impl;

 private:
  explicit HttpServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace kinemo::studio
