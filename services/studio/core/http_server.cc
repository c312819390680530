// The studio's HTTP + WebSocket server (http_server.h), on Boost.Beast.
#include "services/studio/core/http_server.h"

#include <boost/asio/dispatch.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>
#include <type_traits>
#include <unordered_set>
#include <vector>

#include "common/logging/log.h"
#include "common/metrics/metrics.h"
#include "services/studio/core/auth.h"
#include "services/studio/core/messages.h"

namespace kinemo::studio {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using tcp = net::ip::tcp;
using TlsStream = beast::ssl_stream<beast::tcp_stream>;

namespace {

constexpr std::size_t kMaxQueuedBytesBase = 64u << 20;  // beyond max_upload_bytes
constexpr auto kHttpTimeout = std::chrono::seconds(30);
constexpr std::size_t kReadPieceBytes = 64 * 1024;  // socket messages are read in pieces this large

// What Shutdown sees of an open WebSocket, plain or over TLS.
class SocketSession {
 public:
  virtual ~SocketSession() = default;
  // Thread-safe: closes the socket with `code` (after the queued frames).
  virtual void Close(websocket::close_code code) = 0;
};

}  // namespace

// Shared by every session: the options, the router, the handler factory,
// the live sockets (for Shutdown).
class HttpServer::Impl {
 public:
  Impl(const v1::StudioOptions& options, std::shared_ptr<const Router> router, HandlerFactory make_handler,
       std::function<std::string()> health_body)
      : options(options),
        router(std::move(router)),
        make_handler(std::move(make_handler)),
        health_body(std::move(health_body)),
        ioc(static_cast<int>(options.io_threads())),
        acceptor(net::make_strand(ioc)) {}

  // Makes `tls` from server.tls (cert_file, key_file; client_ca_file: the
  // page's browser must present a certificate from that CA).
  Status LoadTls();
  Status Listen();
  void Accept();
  void Register(const std::shared_ptr<SocketSession>& s);
  void Unregister(SocketSession* s);

  const v1::StudioOptions options;
  const std::shared_ptr<const Router> router;
  const HandlerFactory make_handler;
  const std::function<std::string()> health_body;
  // Declared before the io_context: sessions still queued in it when it is
  // destroyed unregister themselves here.
  std::mutex mu;
  std::condition_variable cv;
  std::unordered_set<SocketSession*> live;              // guarded by mu
  std::vector<std::weak_ptr<SocketSession>> live_refs;  // guarded by mu (for Shutdown)
  bool shut_down = false;                               // guarded by mu
  // HTTPS and WSS when server.tls is set (outlives the sessions in ioc).
  std::optional<net::ssl::context> tls;
  net::io_context ioc;
  tcp::acceptor acceptor;
  std::vector<std::thread> threads;
  int port = 0;
  std::string address;
  std::atomic<int> sockets{0};
  // Made once the port is known (the cookie's name holds it).
  std::unique_ptr<Authenticator> auth;
};

namespace {

// An open WebSocket over `Stream` (TCP, or TLS over TCP): reads text frames
// into its handler, writes queued frames.
template <class Stream>
class WebSocketSession : public SocketSession, public std::enable_shared_from_this<WebSocketSession<Stream>> {
 public:
  using std::enable_shared_from_this<WebSocketSession<Stream>>::shared_from_this;
  using std::enable_shared_from_this<WebSocketSession<Stream>>::weak_from_this;

  // `stream`: the upgraded HTTP connection (its TLS session kept).
  WebSocketSession(Stream&& stream, HttpServer::Impl* server) : ws_(std::move(stream)), server_(server) {}

  ~WebSocketSession() {
    if (handler_ != nullptr) handler_->OnClose();
    server_->Unregister(this);
  }

  // Accepts the upgrade `request` and starts reading.
  void Start(http::request<http::string_body> request) {
    request_ = std::move(request);
    beast::get_lowest_layer(ws_).expires_never();
    websocket::stream_base::timeout timeout = websocket::stream_base::timeout::suggested(beast::role_type::server);
    timeout.idle_timeout = std::chrono::seconds(60);
    timeout.keep_alive_pings = true;
    ws_.set_option(timeout);
    ws_.set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, "kinemo-studio"); }));
    // The message limit is checked here, not by Beast: Beast 1.74 fails an
    // oversized message by closing the TCP connection with the rest of the
    // message unread, which resets it, so that the page never sees the close
    // code (its teardown drains one read only). Closing with async_close
    // instead reads and discards until the page's own close frame.
    ws_.read_message_max(0);
    ws_.async_accept(request_, beast::bind_front_handler(&WebSocketSession::OnAccept, shared_from_this()));
  }

  // Thread-safe: queues a frame on the session's strand.
  void Send(std::string text) {
    net::post(ws_.get_executor(), [self = shared_from_this(), text = std::move(text)]() mutable {
      self->Queue(std::move(text));
    });
  }

  void Close(websocket::close_code code) override {
    net::post(ws_.get_executor(), [self = shared_from_this(), code] { self->DoClose(code); });
  }

 private:
  // The handler's view of this session: a weak reference, so that calls
  // still running after the socket closed do nothing.
  class Connection : public SocketConnection {
   public:
    explicit Connection(std::weak_ptr<WebSocketSession> session) : session_(std::move(session)) {}
    void Send(std::string text) override {
      if (auto s = session_.lock()) s->Send(std::move(text));
    }
    void Close() override {
      if (auto s = session_.lock()) s->Close(websocket::close_code::normal);
    }

   private:
    std::weak_ptr<WebSocketSession> session_;
  };

  void OnAccept(beast::error_code ec) {
    if (ec) {
      log::Debug("websocket_accept_failed", {{"error", ec.message()}});
      return;
    }
    handler_ = server_->make_handler(std::make_shared<Connection>(weak_from_this()));
    Read();
  }

  // Reads the next message in pieces (so that its size is known before it
  // is all in memory).
  void Read() {
    ws_.async_read_some(buffer_, kReadPieceBytes,
                        beast::bind_front_handler(&WebSocketSession::OnRead, shared_from_this()));
  }

  void OnRead(beast::error_code ec, std::size_t) {
    // A failed write closes the session while this read is pending, and the
    // read may still complete with a message Beast had buffered: the handler
    // is gone then (it was a null dereference), so the message is dropped.
    if (closed_) return;
    if (!ec && buffer_.size() > server_->options.max_upload_bytes()) {
      buffer_.consume(buffer_.size());
      if (closing_) return;  // a close handshake is already under way
      log::Info("websocket_message_too_big", {{"max_upload_bytes", server_->options.max_upload_bytes()}});
      // No more answers (the one being written, if any, finishes first).
      while (queue_.size() > 1) {
        queued_bytes_ -= queue_.back().size();
        queue_.pop_back();
      }
      closing_ = true;
      ws_.async_close(websocket::close_code::too_big, [self = shared_from_this()](beast::error_code) {
        self->Closed();
      });
      return;
    }
    if (!ec && !ws_.is_message_done()) return Read();
    if (ec) {
      if (ec != websocket::error::closed && ec != net::error::operation_aborted) {
        log::Debug("websocket_read_ended", {{"error", ec.message()}});
      }
      Closed();
      return;
    }
    if (ws_.got_text()) {
      const auto data = buffer_.data();
      handler_->OnText(std::string_view(static_cast<const char*>(data.data()), data.size()));
    } else {
      Queue(EncodeError(0, InvalidField("message", "binary frames are not accepted; send the JSON of a "
                                                   "kinemo.studio.v1.ClientMessage as text")));
    }
    buffer_.consume(buffer_.size());
    if (!closed_) Read();
  }

  void Queue(std::string text) {
    if (closed_ || closing_) return;
    queued_bytes_ += text.size();
    if (queued_bytes_ > kMaxQueuedBytesBase + server_->options.max_upload_bytes()) {
      log::Warn("websocket_slow_reader", {{"queued_bytes", static_cast<long long>(queued_bytes_)}});
      DoClose(websocket::close_code::policy_error);
      return;
    }
    queue_.push_back(std::move(text));
    if (queue_.size() == 1) Write();
  }

  void Write() {
    ws_.text(true);
    ws_.async_write(net::buffer(queue_.front()),
                    beast::bind_front_handler(&WebSocketSession::OnWrite, shared_from_this()));
  }

  void OnWrite(beast::error_code ec, std::size_t) {
    queued_bytes_ -= queue_.front().size();
    queue_.pop_front();
    if (ec || closed_) {
      Closed();  // no-op once closed: the queue is already empty then
      return;
    }
    if (!queue_.empty()) {
      Write();
    } else if (close_after_writes_) {
      StartClose();
    }
  }

  void DoClose(websocket::close_code code) {
    if (closed_ || closing_) return;
    close_code_ = code;
    if (!queue_.empty()) {
      close_after_writes_ = true;  // after the frames already queued
      return;
    }
    StartClose();
  }

  void StartClose() {
    if (closing_) return;  // one close handshake at a time
    closing_ = true;
    ws_.async_close(close_code_, [self = shared_from_this()](beast::error_code) { self->Closed(); });
  }

  // No more reads or writes: tell the handler now (its calls are cancelled),
  // not when the last reference goes.
  void Closed() {
    if (closed_) return;
    closed_ = true;
    // A non-empty queue means a write is in flight, and it still reads the
    // front frame: that one goes in its OnWrite, the rest now. (Clearing it
    // here freed the buffer under the write and let OnWrite pop an empty
    // queue: heap corruption when a page's socket failed mid-write.)
    while (queue_.size() > 1) {
      queued_bytes_ -= queue_.back().size();
      queue_.pop_back();
    }
    if (handler_ != nullptr) {
      handler_->OnClose();
      handler_.reset();
    }
  }

  // Without permessage-deflate (never offered: its option is off by default),
  // so its code is not compiled: this file took 70.6 s with it, 64.5 s
  // without.
  websocket::stream<Stream, /*deflateSupported=*/false> ws_;
  HttpServer::Impl* server_;
  http::request<http::string_body> request_;
  beast::flat_buffer buffer_;
  std::unique_ptr<SocketHandler> handler_;
  std::deque<std::string> queue_;
  std::size_t queued_bytes_ = 0;
  bool closed_ = false, closing_ = false, close_after_writes_ = false;
  websocket::close_code close_code_ = websocket::close_code::normal;
};

// One HTTP connection over `Stream` (TCP, or TLS over TCP): the TLS
// handshake, then requests in order, keep-alive, upgrade to a WebSocket.
template <class Stream>
class HttpSession : public std::enable_shared_from_this<HttpSession<Stream>> {
 public:
  using std::enable_shared_from_this<HttpSession<Stream>>::shared_from_this;
  static constexpr bool kTls = std::is_same_v<Stream, TlsStream>;

  // `client`: the peer's IP address; `args` make the stream (the socket,
  // and the TLS context for TLS).
  template <class... Args>
  HttpSession(HttpServer::Impl* server, std::string client, Args&&... args)
      : stream_(std::forward<Args>(args)...), server_(server), client_(std::move(client)) {}

  void Start() {
    net::dispatch(stream_.get_executor(), beast::bind_front_handler(&HttpSession::Handshake, shared_from_this()));
  }

 private:
  void Handshake() {
    if constexpr (kTls) {
      beast::get_lowest_layer(stream_).expires_after(kHttpTimeout);
      stream_.async_handshake(net::ssl::stream_base::server, [self = shared_from_this()](beast::error_code ec) {
        if (ec) {
          log::Debug("tls_handshake_failed", {{"client", self->client_}, {"error", ec.message()}});
          return;
        }
        self->Read();
      });
    } else {
      Read();
    }
  }

  void Read() {
    parser_.emplace();
    parser_->header_limit(16 * 1024);
    parser_->body_limit(64 * 1024);  // GET and HEAD only: no body worth the name
    beast::get_lowest_layer(stream_).expires_after(kHttpTimeout);
    http::async_read(stream_, buffer_, *parser_,
                     beast::bind_front_handler(&HttpSession::OnRead, shared_from_this()));
  }

  void OnRead(beast::error_code ec, std::size_t) {
    if (ec == http::error::end_of_stream || ec == net::error::operation_aborted) return Shutdown();
    if (ec) {
      if (ec == http::error::header_limit || ec == http::error::body_limit) {
        return Reply(Simple(413, "request too large\n", false), false);
      }
      return Shutdown();
    }
    http::request<http::string_body> req = parser_->release();
    const std::string_view target(req.target().data(), req.target().size());
    const HttpReply route =
        server_->router->Route(std::string_view(req.method_string().data(), req.method_string().size()), target);
    const bool keep_alive = req.keep_alive();
    const bool head = req.method() == http::verb::head;
    if (route.health) {
      return Reply(Simple(200, server_->health_body(), keep_alive, route.content_type, head), keep_alive);
    }
    // Everything else needs the token (before anything runs or is read).
    const auto cookie = req[http::field::cookie];
    const auto authorization = req[http::field::authorization];
    const Authenticator::Outcome outcome =
        server_->auth->Check(client_, std::string_view(cookie.data(), cookie.size()),
                             std::string_view(authorization.data(), authorization.size()), target);
    if (outcome == Authenticator::Outcome::kThrottled) {
      static auto& throttled = metrics::Counter("kinemo_studio_auth_refusals_total",
                                                   "Requests refused for want of the token", {{"reason", "throttled"}});
      throttled.Increment();
      auto res = Simple(429, "too many failed attempts from this address; try again later\n", keep_alive,
                        "text/plain; charset=utf-8", head);
      res->set(http::field::retry_after, std::to_string(std::max(1, server_->auth->RetryAfterSeconds(client_))));
      return Reply(std::move(res), keep_alive);
    }
    if (outcome == Authenticator::Outcome::kMissing || outcome == Authenticator::Outcome::kWrong) {
      static auto& missing = metrics::Counter("kinemo_studio_auth_refusals_total",
                                                 "Requests refused for want of the token", {{"reason", "missing"}});
      static auto& wrong = metrics::Counter("kinemo_studio_auth_refusals_total",
                                               "Requests refused for want of the token", {{"reason", "wrong"}});
      (outcome == Authenticator::Outcome::kMissing ? missing : wrong).Increment();
      if (outcome == Authenticator::Outcome::kWrong) log::Warn("auth_failed", {{"client", client_}});
      auto res = Simple(401,
                        "401: the studio needs its token: open the URL with ?token= that `kinemo studio` (or the "
                        "studio's \"listening\" log line) printed, or send Authorization: Bearer <token>\n",
                        keep_alive, "text/plain; charset=utf-8", head);
      res->set(http::field::www_authenticate, "Bearer realm=\"kinemo studio\"");
      return Reply(std::move(res), keep_alive);
    }
    if (route.websocket && websocket::is_upgrade(req)) return Upgrade(std::move(req));
    if (outcome == Authenticator::Outcome::kAllowedFromUrl) {
      // The token leaves the address bar: the same path again, with the cookie.
      std::string location = WithoutQueryParam(target, "token");
      if (location.empty() || location[0] != '/' || location.rfind("//", 0) == 0) location = "/";
      auto res = Simple(303, "", keep_alive, "text/plain; charset=utf-8", head);
      res->set(http::field::location, location);
      res->set(http::field::set_cookie, server_->auth->SetCookieValue());
      return Reply(std::move(res), keep_alive);
    }
    if (route.file_path.empty()) {
      auto res = Simple(route.status, route.body, keep_alive, route.content_type, head);
      if (route.status == 405) res->set(http::field::allow, "GET, HEAD");
      return Reply(std::move(res), keep_alive);
    }
    http::file_body::value_type body;
    beast::error_code fec;
    body.open(route.file_path.c_str(), beast::file_mode::scan, fec);
    if (fec) return Reply(Simple(404, "not found\n", keep_alive), keep_alive);
    const auto size = body.size();
    if (head) {
      auto res = Simple(200, "", keep_alive, route.content_type, true);
      res->content_length(size);
      return Reply(std::move(res), keep_alive);
    }
    auto res = std::make_shared<http::response<http::file_body>>(http::status::ok, 11);
    res->set(http::field::server, "kinemo-studio");
    res->set(http::field::content_type, route.content_type);
    res->set(http::field::cache_control, "no-cache");
    res->set("X-Content-Type-Options", "nosniff");
    res->body() = std::move(body);
    res->content_length(size);
    res->keep_alive(keep_alive);
    Reply(std::move(res), keep_alive);
  }

  using StringResponse = http::response<http::string_body>;

  std::shared_ptr<StringResponse> Simple(unsigned status, std::string body, bool keep_alive,
                                         const std::string& type = "text/plain; charset=utf-8", bool head = false) {
    auto res = std::make_shared<StringResponse>(static_cast<http::status>(status), 11);
    res->set(http::field::server, "kinemo-studio");
    res->set(http::field::content_type, type);
    res->set(http::field::cache_control, "no-cache");
    res->set("X-Content-Type-Options", "nosniff");
    res->keep_alive(keep_alive);
    const auto length = body.size();
    if (!head) res->body() = std::move(body);
    res->content_length(length);
    return res;
  }

  template <class Response>
  void Reply(std::shared_ptr<Response> res, bool keep_alive) {
    http::async_write(stream_, *res,
                      [self = shared_from_this(), res, keep_alive](beast::error_code ec, std::size_t) {
                        if (ec || !keep_alive) return self->Shutdown();
                        self->Read();
                      });
  }

  void Upgrade(http::request<http::string_body> req) {
    const auto origin = req[http::field::origin];
    const auto host = req[http::field::host];
    std::vector<std::string> allowed(server_->options.allowed_origins().begin(),
                                     server_->options.allowed_origins().end());
    if (!OriginAllowed(std::string_view(origin.data(), origin.size()), std::string_view(host.data(), host.size()),
                       allowed)) {
      log::Warn("websocket_origin_refused", {{"origin", std::string(origin)}, {"host", std::string(host)}});
      return Reply(Simple(403, "origin not allowed\n", false), false);
    }
    if (server_->sockets.load() >= static_cast<int>(server_->options.max_connections())) {
      return Reply(Simple(503, "too many open sockets\n", false), false);
    }
    auto session = std::make_shared<WebSocketSession<Stream>>(std::move(stream_), server_);
    server_->Register(session);
    session->Start(std::move(req));
  }

  void Shutdown() {
    if constexpr (kTls) {
      beast::get_lowest_layer(stream_).expires_after(std::chrono::seconds(5));
      stream_.async_shutdown([self = shared_from_this()](beast::error_code) {});
    } else {
      beast::error_code ec;
      stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
    }
  }

  Stream stream_;
  HttpServer::Impl* server_;
  std::string client_;  // the peer's IP address (the throttle's key)
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
};

}  // namespace

Status HttpServer::Impl::LoadTls() {
  const auto& t = options.server().tls();
  if (t.cert_file().empty()) return absl::OkStatus();
  net::ssl::context ctx(net::ssl::context::tls_server);
  ctx.set_options(net::ssl::context::default_workarounds | net::ssl::context::no_sslv2 |
                  net::ssl::context::no_sslv3 | net::ssl::context::no_tlsv1 | net::ssl::context::no_tlsv1_1 |
                  net::ssl::context::single_dh_use);
  beast::error_code ec;
  ctx.use_certificate_chain_file(t.cert_file(), ec);
  if (ec) return InvalidField("server.tls.cert_file", "\"", t.cert_file(), "\": ", ec.message());
  ctx.use_private_key_file(t.key_file(), net::ssl::context::pem, ec);
  if (ec) return InvalidField("server.tls.key_file", "\"", t.key_file(), "\": ", ec.message());
  if (!t.client_ca_file().empty()) {
    ctx.load_verify_file(t.client_ca_file(), ec);
    if (ec) return InvalidField("server.tls.client_ca_file", "\"", t.client_ca_file(), "\": ", ec.message());
    ctx.set_verify_mode(net::ssl::verify_peer | net::ssl::verify_fail_if_no_peer_cert);
  }
  tls.emplace(std::move(ctx));
  return absl::OkStatus();
}

Status HttpServer::Impl::Listen() {
  beast::error_code ec;
  std::string host = options.server().host();
  if (host == "localhost") host = "127.0.0.1";
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  const auto ip = net::ip::make_address(host, ec);
  if (ec) return InvalidField("server.host", "\"", options.server().host(), "\" is not an IP address");
  const tcp::endpoint endpoint(ip, static_cast<unsigned short>(options.server().port()));
  acceptor.open(endpoint.protocol(), ec);
  if (!ec) acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) acceptor.bind(endpoint, ec);
  if (!ec) acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) {
    return absl::UnavailableError(kinemo::StrCat("server: cannot listen on ", options.server().host(), ":",
                                                 options.server().port(), ": ", ec.message()));
  }
  port = acceptor.local_endpoint().port();
  address = (ip.is_v6() ? "[" + ip.to_string() + "]" : ip.to_string()) + ":" + std::to_string(port);
  return absl::OkStatus();
}

void HttpServer::Impl::Accept() {
  acceptor.async_accept(net::make_strand(ioc), [this](beast::error_code ec, tcp::socket socket) {
    if (ec) {
      if (ec == net::error::operation_aborted || !acceptor.is_open()) return;
      log::Warn("accept_failed", {{"error", ec.message()}});
    } else {
      beast::error_code nodelay_ec;
      socket.set_option(tcp::no_delay(true), nodelay_ec);  // live frames go out at once
      beast::error_code remote_ec;
      const auto remote = socket.remote_endpoint(remote_ec);
      std::string client = remote_ec ? "" : remote.address().to_string();
      if (tls) {
        std::make_shared<HttpSession<TlsStream>>(this, std::move(client), std::move(socket), *tls)->Start();
      } else {
        std::make_shared<HttpSession<beast::tcp_stream>>(this, std::move(client), std::move(socket))->Start();
      }
    }
    Accept();
  });
}

void HttpServer::Impl::Register(const std::shared_ptr<SocketSession>& s) {
  std::lock_guard<std::mutex> l(mu);
  live.insert(s.get());
  live_refs.push_back(s);
  ++sockets;
  if (shut_down) s->Close(websocket::close_code::going_away);
}

void HttpServer::Impl::Unregister(SocketSession* s) {
  std::lock_guard<std::mutex> l(mu);
  if (live.erase(s) > 0) --sockets;
  std::erase_if(live_refs, [](const std::weak_ptr<SocketSession>& w) { return w.expired(); });
  cv.notify_all();
}

HttpServer::HttpServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

HttpServer::~HttpServer() { Shutdown(0); }

StatusOr<std::unique_ptr<HttpServer>> HttpServer::Start(const v1::StudioOptions& options,
                                                        std::shared_ptr<const Router> router,
                                                        HandlerFactory make_handler,
                                                        std::function<std::string()> health_body) {
  auto impl = std::make_unique<Impl>(options, std::move(router), std::move(make_handler), std::move(health_body));
  KINEMO_RETURN_IF_ERROR(impl->LoadTls());
  KINEMO_RETURN_IF_ERROR(impl->Listen());
  if (options.auth().token().empty()) return InvalidField("auth.token", "not resolved (ResolveStudioOptions)");
  impl->auth = std::make_unique<Authenticator>(options.auth().token(), options.auth().max_failures_per_minute(),
                                               impl->port, impl->tls.has_value());
  impl->Accept();
  for (std::uint32_t i = 0; i < options.io_threads(); ++i) {
    impl->threads.emplace_back([io = &impl->ioc] { io->run(); });
  }
  return std::unique_ptr<HttpServer>(new HttpServer(std::move(impl)));
}

int HttpServer::port() const { return impl_->port; }
std::string HttpServer::address() const { return impl_->address; }
int HttpServer::open_sockets() const { return impl_->sockets.load(); }

void HttpServer::Shutdown(double grace_s) {
  Impl& s = *impl_;
  std::vector<std::shared_ptr<SocketSession>> open;
  {
    std::lock_guard<std::mutex> l(s.mu);
    if (s.shut_down && s.threads.empty()) return;
    s.shut_down = true;
    for (const auto& w : s.live_refs) {
      if (auto p = w.lock()) open.push_back(std::move(p));
    }
  }
  net::post(s.acceptor.get_executor(), [&s] {
    beast::error_code ec;
    s.acceptor.close(ec);
  });
  for (const auto& p : open) p->Close(websocket::close_code::going_away);
  open.clear();
  {
    std::unique_lock<std::mutex> l(s.mu);
    s.cv.wait_for(l, std::chrono::duration<double>(grace_s), [&s] { return s.live.empty(); });
  }
  s.ioc.stop();
  for (auto& t : s.threads) t.join();
  s.threads.clear();
}

}  // namespace kinemo::studio
