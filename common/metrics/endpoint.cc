// GET /metrics over HTTP or HTTPS (metrics.h: MetricsEndpoint), on
// Boost.Beast: one I/O thread, one short request per scrape. With
// MetricsOptions.tls the endpoint speaks only TLS (client_ca_file: a client
// certificate from that CA is required during the handshake); with
// bearer_token_file every request needs `Authorization: Bearer <token>`
// (401 otherwise, compared in constant time).
#include <openssl/crypto.h>
#include <openssl/sha.h>

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>

#include <array>
#include <chrono>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>
#include <thread>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/metrics/metrics.h"

namespace kinemo::metrics {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;

namespace {

constexpr auto kConnectionTimeout = std::chrono::seconds(10);
constexpr std::size_t kMaxSecretFileBytes = 1 << 20;

using Digest = std::array<unsigned char, SHA256_DIGEST_LENGTH>;

Digest Sha256(std::string_view text) {
  Digest d;
  SHA256(reinterpret_cast<const unsigned char*>(text.data()), text.size(), d.data());
  return d;
}

// A whole small file; INVALID_ARGUMENT naming `field` when it cannot be read.
StatusOr<std::string> ReadSmallFile(const std::string& path, const std::string& field) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::InvalidArgumentError(absl::StrCat(field, ": cannot read '", path, "'"));
  std::string text;
  text.resize(kMaxSecretFileBytes + 1);
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (text.size() > kMaxSecretFileBytes) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": '", path, "' is larger than 1 MiB"));
  }
  return text;
}

}  // namespace

struct MetricsEndpoint::Impl {
  std::optional<net::ssl::context> tls;
  // SHA-256 of the bearer token (compared digest to digest: the time taken
  // says nothing of the token's length or of where a guess differs).
  std::optional<Digest> token_digest;
  net::io_context ioc{1};
  tcp::acceptor acceptor{net::make_strand(ioc)};
  std::thread thread;

  Status LoadTls(const common::v1::TlsOptions& options);
  void Accept();
  // The answer to one request.
  http::response<http::string_body> Answer(const http::request<http::string_body>& request) const;
};

Status MetricsEndpoint::Impl::LoadTls(const common::v1::TlsOptions& options) {
  if (options.cert_file().empty() || options.key_file().empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "server.metrics.tls.", options.cert_file().empty() ? "cert_file" : "key_file",
        ": required for HTTPS (with server.metrics.tls set)"));
  }
  tls.emplace(net::ssl::context::tls_server);
  tls->set_options(net::ssl::context::default_workarounds | net::ssl::context::no_sslv2 |
                   net::ssl::context::no_sslv3 | net::ssl::context::no_tlsv1 | net::ssl::context::no_tlsv1_1 |
                   net::ssl::context::single_dh_use);
  struct File {
    const std::string& path;
    const char* field;
  };
  for (const File& f : {File{options.cert_file(), "cert_file"}, File{options.key_file(), "key_file"},
                        File{options.client_ca_file(), "client_ca_file"}}) {
    const std::string kind = f.field;
    if (f.path.empty()) continue;
    const std::string field = absl::StrCat("server.metrics.tls.", f.field);
    KINEMO_ASSIGN_OR_RETURN(std::string pem, ReadSmallFile(f.path, field));
    beast::error_code ec;
    const net::const_buffer buffer(pem.data(), pem.size());
    if (kind == "cert_file") {
      tls->use_certificate_chain(buffer, ec);
    } else if (kind == "key_file") {
      tls->use_private_key(buffer, net::ssl::context::pem, ec);
    } else {
      tls->add_certificate_authority(buffer, ec);
      if (!ec) {
        tls->set_verify_mode(net::ssl::verify_peer | net::ssl::verify_fail_if_no_peer_cert);
      }
    }
    if (ec) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ": '", f.path, "' is not usable PEM (", ec.message(), ")"));
    }
  }
  if (SSL_CTX_check_private_key(tls->native_handle()) != 1) {
    return absl::InvalidArgumentError(absl::StrCat("server.metrics.tls.key_file: '", options.key_file(),
                                                   "' does not match server.metrics.tls.cert_file"));
  }
  return absl::OkStatus();
}

http::response<http::string_body> MetricsEndpoint::Impl::Answer(
    const http::request<http::string_body>& request) const {
  http::response<http::string_body> res;
  res.version(request.version());
  res.keep_alive(request.keep_alive());
  res.set(http::field::server, "kinemo-metrics");
  res.set(http::field::content_type, "text/plain; charset=utf-8");
  if (token_digest.has_value()) {
    const std::string auth(request[http::field::authorization]);
    const std::string scheme = "Bearer ";
    const bool bearer = auth.size() > scheme.size() && absl::EqualsIgnoreCase(auth.substr(0, scheme.size()), scheme);
    const Digest got = Sha256(bearer ? std::string_view(auth).substr(scheme.size()) : std::string_view());
    if (!bearer || CRYPTO_memcmp(got.data(), token_digest->data(), got.size()) != 0) {
      res.result(http::status::unauthorized);
      res.set(http::field::www_authenticate, "Bearer realm=\"kinemo metrics\"");
      res.body() = "a bearer token is required (server.metrics.bearer_token_file)\n";
      res.prepare_payload();
      return res;
    }
  }
  const std::string target(request.target());
  if (target != "/metrics" && target.rfind("/metrics?", 0) != 0) {
    res.result(http::status::not_found);
    res.body() = "only GET /metrics is served here\n";
  } else if (request.method() != http::verb::get) {
    res.result(http::status::method_not_allowed);
    res.set(http::field::allow, "GET");
    res.body() = "GET only\n";
  } else {
    res.result(http::status::ok);
    res.set(http::field::content_type, "text/plain; version=0.0.4; charset=utf-8");
    res.body() = TextExposition();
  }
  res.prepare_payload();
  return res;
}

namespace {

// One connection: (TLS handshake,) requests and answers until the client
// closes, a request asks to close, or kConnectionTimeout passes idle.
template <class Stream>
class Connection : public std::enable_shared_from_this<Connection<Stream>> {
 public:
  template <class... Args>
  Connection(const MetricsEndpoint::Impl* endpoint, Args&&... args)
      : endpoint_(endpoint), stream_(std::forward<Args>(args)...) {}

  void Run() {
    beast::get_lowest_layer(stream_).expires_after(kConnectionTimeout);
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
      Read();
    } else {
      stream_.async_handshake(net::ssl::stream_base::server,
                              [self = this->shared_from_this()](beast::error_code ec) {
                                if (!ec) self->Read();
                              });
    }
  }

 private:
  void Read() {
    request_ = {};
    parser_.emplace();
    parser_->body_limit(4096);
    beast::get_lowest_layer(stream_).expires_after(kConnectionTimeout);
    http::async_read(stream_, buffer_, *parser_,
                     [self = this->shared_from_this()](beast::error_code ec, std::size_t) { self->OnRead(ec); });
  }

  void OnRead(beast::error_code ec) {
    if (ec) return Close();
    request_ = parser_->release();
    response_ = endpoint_->Answer(request_);
    http::async_write(stream_, response_, [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) return;
      if (self->response_.keep_alive()) return self->Read();
      self->Close();
    });
  }

  void Close() {
    if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
      beast::error_code ignored;
      stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    } else {
      beast::get_lowest_layer(stream_).expires_after(std::chrono::seconds(2));
      stream_.async_shutdown([self = this->shared_from_this()](beast::error_code) {});
    }
  }

  const MetricsEndpoint::Impl* endpoint_;
  Stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  http::request<http::string_body> request_;
  http::response<http::string_body> response_;
};

}  // namespace

void MetricsEndpoint::Impl::Accept() {
  acceptor.async_accept(net::make_strand(ioc), [this](beast::error_code ec, tcp::socket socket) {
    if (ec == net::error::operation_aborted) return;
    if (!ec) {
      if (tls.has_value()) {
        std::make_shared<Connection<beast::ssl_stream<beast::tcp_stream>>>(this, std::move(socket), *tls)->Run();
      } else {
        std::make_shared<Connection<beast::tcp_stream>>(this, std::move(socket))->Run();
      }
    }
    Accept();
  });
}

StatusOr<std::unique_ptr<MetricsEndpoint>> MetricsEndpoint::Start(const common::v1::MetricsOptions& options) {
  const std::string host = options.host().empty() ? "127.0.0.1" : options.host();
  const bool ipv6 = host.find(':') != std::string::npos && host.front() != '[';
  const std::string bind = absl::StrCat(ipv6 ? "[" : "", host, ipv6 ? "]" : "", ":", options.port());
  auto endpoint = std::unique_ptr<MetricsEndpoint>(new MetricsEndpoint());
  endpoint->impl_ = std::make_unique<Impl>();
  Impl& impl = *endpoint->impl_;
  if (options.has_tls()) KINEMO_RETURN_IF_ERROR(impl.LoadTls(options.tls()));
  if (!options.bearer_token_file().empty()) {
    KINEMO_ASSIGN_OR_RETURN(std::string token,
                            ReadSmallFile(options.bearer_token_file(), "server.metrics.bearer_token_file"));
    const std::string trimmed(absl::StripAsciiWhitespace(token));
    if (trimmed.empty()) {
      return absl::InvalidArgumentError(absl::StrCat("server.metrics.bearer_token_file: '",
                                                     options.bearer_token_file(), "' holds no token"));
    }
    impl.token_digest = Sha256(trimmed);
  }
  // "localhost" and bracketed IPv6 as the resolver takes them.
  std::string resolve_host = host;
  if (resolve_host.size() > 2 && resolve_host.front() == '[' && resolve_host.back() == ']') {
    resolve_host = resolve_host.substr(1, resolve_host.size() - 2);
  }
  beast::error_code ec;
  tcp::resolver resolver(impl.ioc);
  const auto results = resolver.resolve(resolve_host, std::to_string(options.port()), ec);
  if (ec || results.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("server.metrics.host: cannot resolve '", host, "' (", ec.message(), ")"));
  }
  const tcp::endpoint at = results.begin()->endpoint();
  impl.acceptor.open(at.protocol(), ec);
  if (!ec) impl.acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) impl.acceptor.bind(at, ec);
  if (!ec) impl.acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) {
    return absl::UnavailableError(absl::StrCat("server.metrics.port: cannot listen on ", bind,
                                               " for /metrics (", ec.message(), ")"));
  }
  endpoint->port_ = impl.acceptor.local_endpoint().port();
  endpoint->address_ = absl::StrCat(ipv6 ? "[" : "", host, ipv6 ? "]" : "", ":", endpoint->port_);
  impl.Accept();
  impl.thread = std::thread([&impl] { impl.ioc.run(); });
  return endpoint;
}

MetricsEndpoint::~MetricsEndpoint() {
  if (impl_ == nullptr) return;
  impl_->ioc.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

}  // namespace kinemo::metrics
