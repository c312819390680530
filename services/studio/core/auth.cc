// The studio's authentication (auth.h).
#include "services/studio/core/auth.h"


#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <stdexcept>

#include "services/studio/core/routes.h"

namespace kinemo::studio {
namespace {

// Addresses with failures remembered at once; beyond it full buckets are
// dropped, and if that is not enough new addresses are throttled (fail
// closed) until the table shrinks.
constexpr std::size_t kPruneAbove = 4096;
constexpr std::size_t kMaxAddresses = 65536;

bool StartsWithNoCase(std::string_view s, std::string_view prefix) {
  if (s.size() < prefix.size()) return false;
  for (std::size_t i = 0; i < prefix.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(s[i])) != std::tolower(static_cast<unsigned char>(prefix[i]))) {
      return false;
    }
  }
  return true;
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

}  // namespace

bool ConstantTimeEquals(std::string_view a, std::string_view b) {
  // Every byte of `a` is looked at whatever `b` holds; the lengths are not
  // secret (tokens have a fixed length).
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const unsigned char other = b.empty() ? 0 : static_cast<unsigned char>(b[i % b.size()]);
    diff |= static_cast<unsigned char>(static_cast<unsigned char>(a[i]) ^ other);
  }
  // Opaque to the optimiser: no early exit is introduced.
  volatile unsigned char result = diff;
  return result == 0;
}

std::string_view CookieValue(std::string_view cookie_header, std::string_view name) {
  while (!cookie_header.empty()) {
    const std::size_t end = std::min(cookie_header.find(';'), cookie_header.size());
    const std::string_view pair = Trim(cookie_header.substr(0, end));
    const std::size_t eq = pair.find('=');
    if (eq != std::string_view::npos && Trim(pair.substr(0, eq)) == name) return Trim(pair.substr(eq + 1));
    cookie_header.remove_prefix(std::min(end + 1, cookie_header.size()));
  }
  return {};
}

std::string QueryValue(std::string_view target, std::string_view name) {
  const std::size_t q = target.find('?');
  if (q == std::string_view::npos) return "";
  std::string_view query = target.substr(q + 1);
  while (!query.empty()) {
    const std::size_t end = std::min(query.find('&'), query.size());
    const std::string_view pair = query.substr(0, end);
    const std::size_t eq = pair.find('=');
    if (pair.substr(0, eq) == name && eq != std::string_view::npos) {
      std::string value;
      return DecodePath(pair.substr(eq + 1), &value) ? value : "";
    }
    query.remove_prefix(std::min(end + 1, query.size()));
  }
  return "";
}

std::string WithoutQueryParam(std::string_view target, std::string_view name) {
  const std::size_t q = target.find('?');
  if (q == std::string_view::npos) return std::string(target);
  std::string out(target.substr(0, q));
  std::string_view query = target.substr(q + 1);
  char sep = '?';
  while (!query.empty()) {
    const std::size_t end = std::min(query.find('&'), query.size());
    const std::string_view pair = query.substr(0, end);
    if (!pair.empty() && pair.substr(0, pair.find('=')) != name) {
      out.push_back(sep);
      out.append(pair);
      sep = '&';
    }
    query.remove_prefix(std::min(end + 1, query.size()));
  }
  return out;
}

Authenticator::Authenticator(std::string token, std::uint32_t max_failures_per_minute, int port, bool secure)
    : token_(std::move(token)),
      max_failures_(std::max<std::uint32_t>(1, max_failures_per_minute)),
      cookie_name_("kinemo-studio-" + std::to_string(port)),
      secure_(secure) {}

void Authenticator::Refill(Bucket* b, Clock::time_point now) const {
  const double elapsed_s = std::chrono::duration<double>(now - b->updated).count();
  if (elapsed_s > 0) b->tokens = std::min(max_failures_, b->tokens + elapsed_s * max_failures_ / 60.0);
  b->updated = std::max(b->updated, now);
}

void Authenticator::Prune(Clock::time_point now) {
  if (failures_.size() <= kPruneAbove) return;
  for (auto& [client, bucket] : failures_) Refill(&bucket, now);
  std::erase_if(failures_, [&](const auto& entry) { return entry.second.tokens >= max_failures_; });
}

Authenticator::Outcome Authenticator::Check(std::string_view client, std::string_view cookie_header,
                                            std::string_view authorization, std::string_view target,
                                            Clock::time_point now) {
  const std::string key(client);
  std::lock_guard<std::mutex> l(mu_);
  auto it = failures_.find(key);
  if (it != failures_.end()) {
    Refill(&it->second, now);
    if (it->second.tokens < 1) return Outcome::kThrottled;
  }
  const std::string_view cookie = CookieValue(cookie_header, cookie_name_);
  std::string_view bearer;
  authorization = Trim(authorization);
  if (StartsWithNoCase(authorization, "Bearer ")) bearer = Trim(authorization.substr(7));
  const std::string from_url = QueryValue(target, "token");
  if (cookie.empty() && bearer.empty() && from_url.empty()) return Outcome::kMissing;
  // Each presented credential is compared (no early exit on the first).
  const bool cookie_ok = !cookie.empty() && ConstantTimeEquals(cookie, token_);
  const bool bearer_ok = !bearer.empty() && ConstantTimeEquals(bearer, token_);
  const bool url_ok = !from_url.empty() && ConstantTimeEquals(from_url, token_);
  if (cookie_ok || bearer_ok) return Outcome::kAllowed;
  if (url_ok) return Outcome::kAllowedFromUrl;
  if (it == failures_.end()) {
    Prune(now);
    if (failures_.size() >= kMaxAddresses) return Outcome::kThrottled;
    it = failures_.emplace(key, Bucket{max_failures_, now}).first;
  }
  it->second.tokens -= 1;
  return Outcome::kWrong;
}

int Authenticator::RetryAfterSeconds(std::string_view client, Clock::time_point now) {
  std::lock_guard<std::mutex> l(mu_);
  auto it = failures_.find(std::string(client));
  if (it == failures_.end()) return failures_.size() >= kMaxAddresses ? 60 : 0;
  Refill(&it->second, now);
  if (it->second.tokens >= 1) return 0;
  return static_cast<int>(std::ceil((1 - it->second.tokens) * 60.0 / max_failures_));
}

std::string Authenticator::SetCookieValue() const {
  return cookie_name_ + "=" + token_ + "; Path=/; HttpOnly; SameSite=Strict" + (secure_ ? "; Secure" : "");
}

}  // namespace kinemo::studio
