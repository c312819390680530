#include "common/vmc/osc.h"

#include <arpa/inet.h>
#include <lo/lo.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>

namespace kinemo::vmc {

// ---- BundleWriter ------------------------------------------------------------

struct BundleWriter::Impl {
  lo_bundle bundle = nullptr;
  std::size_t messages = 0;
  ~Impl() {
    if (bundle != nullptr) lo_bundle_free_recursive(bundle);
  }
  void Reset() {
    if (bundle != nullptr) lo_bundle_free_recursive(bundle);
    bundle = lo_bundle_new(LO_TT_IMMEDIATE);
    messages = 0;
  }
};

BundleWriter::BundleWriter(std::size_t max_datagram_bytes)
    : max_bytes_(std::max<std::size_t>(max_datagram_bytes, 256)), impl_(std::make_unique<Impl>()) {}

BundleWriter::~BundleWriter() = default;

void BundleWriter::Begin() {
  impl_->Reset();
  count_ = 0;
}

Status BundleWriter::Append(const char* address, void* raw) {
  auto m = static_cast<lo_message>(raw);
  // The bundle's element: a 4-byte size, then the message.
  const std::size_t element = 4 + lo_message_length(m, address);
  if (16 + element > max_bytes_) {
    lo_message_free(m);
    return absl::InvalidArgumentError(
        kinemo::StrCat(address, ": a message of ", element, " bytes does not fit a datagram of ", max_bytes_));
  }
  if (impl_->messages > 0 && lo_bundle_length(impl_->bundle) + element > max_bytes_) {
    KINEMO_RETURN_IF_ERROR(Flush());
  }
  if (lo_bundle_add_message(impl_->bundle, address, m) != 0) {  // (the bundle holds the message from here)
    lo_message_free(m);
    return absl::ResourceExhaustedError(kinemo::StrCat(address, ": liblo could not add the message"));
  }
  ++impl_->messages;
  return absl::OkStatus();
}

Status BundleWriter::Add(const char* address, std::string_view text, std::span<const float> values) {
  lo_message m = lo_message_new();
  if (m == nullptr) return absl::ResourceExhaustedError("liblo: no memory for a message");
  int rc = lo_message_add_string(m, std::string(text).c_str());
  for (float v : values) rc |= lo_message_add_float(m, v);
  if (rc != 0) {
    lo_message_free(m);
    return absl::ResourceExhaustedError(kinemo::StrCat(address, ": liblo could not add an argument"));
  }
  return Append(address, m);
}

Status BundleWriter::AddInts(const char* address, std::span<const std::int32_t> values) {
  lo_message m = lo_message_new();
  if (m == nullptr) return absl::ResourceExhaustedError("liblo: no memory for a message");
  int rc = 0;
  for (std::int32_t v : values) rc |= lo_message_add_int32(m, v);
  if (rc != 0) {
    lo_message_free(m);
    return absl::ResourceExhaustedError(kinemo::StrCat(address, ": liblo could not add an argument"));
  }
  return Append(address, m);
}

Status BundleWriter::AddFloat(const char* address, float value) {
  lo_message m = lo_message_new();
  if (m == nullptr) return absl::ResourceExhaustedError("liblo: no memory for a message");
  if (lo_message_add_float(m, value) != 0) {
    lo_message_free(m);
    return absl::ResourceExhaustedError(kinemo::StrCat(address, ": liblo could not add an argument"));
  }
  return Append(address, m);
}

Status BundleWriter::Flush() {
  if (impl_->messages == 0) return absl::OkStatus();
  if (count_ == datagrams_.size()) datagrams_.emplace_back();
  std::string& out = datagrams_[count_];
  out.resize(lo_bundle_length(impl_->bundle));
  std::size_t size = 0;
  if (lo_bundle_serialise(impl_->bundle, out.data(), &size) == nullptr || size > out.size()) {
    return absl::InternalError("liblo: could not serialise a bundle");
  }
  out.resize(size);
  ++count_;
  impl_->Reset();
  return absl::OkStatus();
}

Status BundleWriter::End() { return Flush(); }

// ---- addresses ---------------------------------------------------------------

StatusOr<Endpoint> ParseEndpoint(std::string_view text, std::string_view field) {
  Endpoint e;
  std::string_view port = text;
  if (!text.empty() && text.front() == '[') {
    const std::size_t close = text.find(']');
    if (close == std::string_view::npos || close + 1 >= text.size() || text[close + 1] != ':') {
      return InvalidField(field, "'", text, "' is not [IPV6]:PORT");
    }
    e.host = std::string(text.substr(1, close - 1));
    port = text.substr(close + 2);
  } else if (const std::size_t colon = text.rfind(':'); colon != std::string_view::npos) {
    if (text.find(':') != colon) return InvalidField(field, "'", text, "': write an IPv6 address as [ADDRESS]:PORT");
    e.host = std::string(text.substr(0, colon));
    port = text.substr(colon + 1);
  } else {
    e.host = "127.0.0.1";
  }
  if (e.host.empty() || e.host.size() > 253) return InvalidField(field, "'", text, "' has no host (HOST:PORT)");
  if (e.host.find_first_of("[]") != std::string::npos) return InvalidField(field, "'", text, "' is not HOST:PORT");
  int value = 0;
  const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
  if (ec != std::errc() || end != port.data() + port.size() || value < 1 || value > 65535) {
    return InvalidField(field, "'", text, "': the port must be a number in 1..65535");
  }
  e.port = value;
  return e;
}

namespace {

bool Loopback(const sockaddr* a) {
  if (a->sa_family == AF_INET) {
    const auto* in = reinterpret_cast<const sockaddr_in*>(a);
    return (ntohl(in->sin_addr.s_addr) >> 24) == 127;
  }
  if (a->sa_family == AF_INET6) {
    const auto* in6 = reinterpret_cast<const sockaddr_in6*>(a);
    if (IN6_IS_ADDR_LOOPBACK(&in6->sin6_addr)) return true;
    return IN6_IS_ADDR_V4MAPPED(&in6->sin6_addr) && in6->sin6_addr.s6_addr[12] == 127;
  }
  return false;
}

struct AddrInfo {
  addrinfo* list = nullptr;
  ~AddrInfo() {
    if (list != nullptr) freeaddrinfo(list);
  }
};

Status Resolve(const std::string& host, int port, AddrInfo* out, std::string_view field) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  const std::string service = std::to_string(port);
  const int rc = getaddrinfo(host.c_str(), service.c_str(), &hints, &out->list);
  if (rc != 0 || out->list == nullptr) {
    return absl::NotFoundError(kinemo::StrCat(field, ": cannot resolve '", host, "': ", gai_strerror(rc)));
  }
  return absl::OkStatus();
}

std::string Numeric(const sockaddr* a, socklen_t len) {
  char host[NI_MAXHOST], port[NI_MAXSERV];
  if (getnameinfo(a, len, host, sizeof host, port, sizeof port, NI_NUMERICHOST | NI_NUMERICSERV) != 0) return "?";
  return a->sa_family == AF_INET6 ? kinemo::StrCat("[", host, "]:", port) : kinemo::StrCat(host, ":", port);
}

}  // namespace

StatusOr<bool> IsLoopbackHost(const std::string& host, std::string_view field) {
  AddrInfo ai;
  KINEMO_RETURN_IF_ERROR(Resolve(host, 9, &ai, field));
  for (const addrinfo* p = ai.list; p != nullptr; p = p->ai_next) {
    if (!Loopback(p->ai_addr)) return false;
  }
  return true;
}

// ---- UdpSender ---------------------------------------------------------------

StatusOr<std::unique_ptr<UdpSender>> UdpSender::Open(const Endpoint& endpoint, bool loopback_only,
                                                     std::string_view field) {
  AddrInfo ai;
  KINEMO_RETURN_IF_ERROR(Resolve(endpoint.host, endpoint.port, &ai, field));
  const addrinfo* a = ai.list;
  if (loopback_only && !Loopback(a->ai_addr)) {
    return absl::PermissionDeniedError(kinemo::StrCat(field, ": ", Numeric(a->ai_addr, a->ai_addrlen),
                                                      " is not a loopback address (only loopback is allowed here)"));
  }
  std::unique_ptr<UdpSender> s(new UdpSender());
  s->fd_ = ::socket(a->ai_family, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (s->fd_ < 0) return absl::InternalError(kinemo::StrCat(field, ": socket: ", std::strerror(errno)));
  if (::connect(s->fd_, a->ai_addr, a->ai_addrlen) != 0) {
    return absl::UnavailableError(kinemo::StrCat(field, ": cannot reach ", Numeric(a->ai_addr, a->ai_addrlen), ": ",
                                                 std::strerror(errno)));
  }
  s->address_ = Numeric(a->ai_addr, a->ai_addrlen);
  return s;
}

UdpSender::~UdpSender() {
  if (fd_ >= 0) ::close(fd_);
}

bool UdpSender::Send(std::string_view datagram) {
  for (int attempt = 0; attempt < 2; ++attempt) {
    const ssize_t n = ::send(fd_, datagram.data(), datagram.size(), MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(datagram.size())) {
      ++sent_;
      return true;
    }
    // A refusal (ICMP port unreachable) reported for an earlier datagram:
    // this one was not sent; try once more.
    if (n < 0 && errno == ECONNREFUSED) continue;
    break;
  }
  ++dropped_;
  return false;
}

}  // namespace kinemo::vmc
