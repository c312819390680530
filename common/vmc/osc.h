// VMC packets: the messages of one frame as OSC bundles (encoded by liblo),
// each at most one UDP datagram of a safe size, and the UDP socket they go
// out on (docs/vmc.md).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::vmc {

// One Ethernet frame (1500) minus the IPv6 (40) and UDP (8) headers: a
// datagram this long is never fragmented on an Ethernet or Wi-Fi LAN, so a
// lost packet loses only its part of a frame.
inline constexpr std::size_t kDefaultMaxDatagramBytes = 1452;

// Builds the datagrams of a frame: messages are added in order and go into
// OSC bundles (timetag "immediately"); when the next message would make the
// bundle longer than the limit, the bundle is closed as one datagram and a
// new one begins. Not thread-safe; reuse one per stream.
class BundleWriter {
 public:
  explicit BundleWriter(std::size_t max_datagram_bytes = kDefaultMaxDatagramBytes);
  ~BundleWriter();
  BundleWriter(const BundleWriter&) = delete;
  BundleWriter& operator=(const BundleWriter&) = delete;

  // Starts a frame (drops what the last one left).
  void Begin();
  // /address with a string then floats (Bone/Pos, Root/Pos, Blend/Val).
  Status Add(const char* address, std::string_view text, std::span<const float> values);
  // /address with int32 arguments (OK) or none (Blend/Apply).
  Status AddInts(const char* address, std::span<const std::int32_t> values);
  // /address with one float (T).
  Status AddFloat(const char* address, float value);
  // Closes the frame: its datagrams, in order.
  Status End();
  std::span<const std::string> datagrams() const { return {datagrams_.data(), count_}; }
  std::size_t max_datagram_bytes() const { return max_bytes_; }

 private:
  struct Impl;
  Status Append(const char* address, void* message);  // takes the liblo message
  Status Flush();
  std::size_t max_bytes_;
  std::unique_ptr<Impl> impl_;
  std::vector<std::string> datagrams_;  // reused
  std::size_t count_ = 0;
};

// A VMC receiver's address: "HOST:PORT", "[IPV6]:PORT" or "PORT" (host
// 127.0.0.1). INVALID_ARGUMENT naming `field` for anything else (empty host,
// port outside 1..65535).
struct Endpoint {
  std::string host;
  int port = 0;
};
StatusOr<Endpoint> ParseEndpoint(std::string_view text, std::string_view field);

// True when every address `host` resolves to is a loopback address
// (127.0.0.0/8, ::1, ::ffff:127.0.0.0/104). NOT_FOUND naming `field` when it
// does not resolve.
StatusOr<bool> IsLoopbackHost(const std::string& host, std::string_view field);

// A connected UDP socket to one receiver. Sends never block: a datagram the
// kernel cannot take at once, or one refused (nothing listening yet), is
// counted as dropped, as VMC senders do (the next frame replaces it).
class UdpSender {
 public:
  // Resolves the endpoint (the first address it has). With `loopback_only`,
  // PERMISSION_DENIED naming `field` unless it is a loopback address.
  static StatusOr<std::unique_ptr<UdpSender>> Open(const Endpoint& endpoint, bool loopback_only,
                                                   std::string_view field);
  ~UdpSender();
  UdpSender(const UdpSender&) = delete;
  UdpSender& operator=(const UdpSender&) = delete;

  // True if the datagram left.
  bool Send(std::string_view datagram);
  std::uint64_t sent() const { return sent_; }
  std::uint64_t dropped() const { return dropped_; }
  // The numeric address sent to ("127.0.0.1:39539", "[::1]:39539").
  const std::string& address() const { return address_; }

 private:
  UdpSender() = default;
  int fd_ = -1;
  std::string address_;
  std::uint64_t sent_ = 0, dropped_ = 0;
};

}  // namespace kinemo::vmc
