// The studio's authentication (StudioAuth in options.proto), without
// sockets: which requests carry the token, the session cookie, and the
// per-address throttle of failed attempts.
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

#include "services/studio/core/token.h"  // NewToken, IsLoopbackHost

namespace kinemo::studio {

// True if `a` and `b` are equal; the time taken depends on their lengths
// only, not on where they differ.
bool ConstantTimeEquals(std::string_view a, std::string_view b);



// The value of cookie `name` in a Cookie header ("a=1; b=2"), or "".
std::string_view CookieValue(std::string_view cookie_header, std::string_view name);

// The value of query parameter `name` in a request target
// ("/path?a=1&token=x"), percent-decoded; "" if absent.
std::string QueryValue(std::string_view target, std::string_view name);

// `target` without its query parameter `name` (the others kept in order).
std::string WithoutQueryParam(std::string_view target, std::string_view name);

class Authenticator {
 public:
  using Clock = std::chrono::steady_clock;

  // `token` non-empty; `max_failures_per_minute` >= 1. `port` names the
  // cookie (cookies are shared by every port of a host).
  Authenticator(std::string token, std::uint32_t max_failures_per_minute, int port, bool secure);

  enum class Outcome {
    kAllowed,          // right token in the cookie or the header
    kAllowedFromUrl,   // right token in ?token=: set the cookie
    kMissing,          // no credentials at all: 401
    kWrong,            // wrong credentials (counted): 401
    kThrottled,        // too many failures from this address: 429, not checked
  };
  // Checks one request from `client` (its IP address). `now` for tests.
  Outcome Check(std::string_view client, std::string_view cookie_header, std::string_view authorization,
                std::string_view target, Clock::time_point now = Clock::now());

  // The Set-Cookie header value carrying the token (HttpOnly,
  // SameSite=Strict, Path=/, Secure over TLS).
  std::string SetCookieValue() const;
  const std::string& cookie_name() const { return cookie_name_; }
  // Seconds until `client` may try again (0 = not throttled).
  int RetryAfterSeconds(std::string_view client, Clock::time_point now = Clock::now());

 private:
  struct Bucket {
    double tokens = 0;  // failures still allowed
    Clock::time_point updated;
  };
  // Refills `b` to `now` (max_failures per minute, capped at max_failures).
  void Refill(Bucket* b, Clock::time_point now) const;
  // Drops full buckets once the table is large (bounded memory).
  void Prune(Clock::time_point now);

  const std::string token_;
  const double max_failures_;
  const std::string cookie_name_;
  const bool secure_;
  std::mutex mu_;
  std::unordered_map<std::string, Bucket> failures_;  // guarded by mu_
};

}  // namespace kinemo::studio
