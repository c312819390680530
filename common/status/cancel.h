// A plain cancellation token for long work in core code (prosody analysis,
// training, controller and graph builds, locomotion evaluation, gesture
// synthesis). The RPC adapter makes one from the call (its deadline and its
// cancellation, common/grpc/cancel_token.h); core loops poll it every so
// often and return its status. Core code never sees gRPC.
//
//   Status Build(..., const CancelToken* cancel) {
//     for (...) {
//       KINEMO_RETURN_IF_ERROR(CheckCancel(cancel, "build"));  // null = never stops
//       ...
//     }
//   }
//
// Thread-safe: Cancel() from any thread; stopped()/Check() from any thread
// (a parallel loop's workers included).
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <string_view>

#include "common/status/status.h"

namespace kinemo {

class CancelToken {
 public:
  using Clock = std::chrono::steady_clock;

  // Never stops unless cancelled.
  CancelToken() = default;
  // Stops at `deadline` (Clock::time_point::max() = none). `probe`, when
  // given, is polled by stopped() for another source of cancellation (e.g.
  // the RPC's own flag); it must stay valid while the token is used.
  explicit CancelToken(Clock::time_point deadline, std::function<bool()> probe = nullptr)
      : deadline_(deadline), probe_(std::move(probe)) {}
  CancelToken(const CancelToken&) = delete;
  CancelToken& operator=(const CancelToken&) = delete;

  void Cancel() { cancelled_.store(true, std::memory_order_relaxed); }

  // Past the deadline (checked on the steady clock).
  bool expired() const { return deadline_ != Clock::time_point::max() && Clock::now() >= deadline_; }
  // Cancelled, the probe says so, or past the deadline.
  bool stopped() const {
    if (cancelled_.load(std::memory_order_relaxed)) return true;
    if (probe_ && probe_()) {
      cancelled_.store(true, std::memory_order_relaxed);
      return true;
    }
    return expired();
  }
  // OK while not stopped; else DEADLINE_EXCEEDED (past the deadline) or
  // CANCELLED, the message starting with `what` (e.g. "value iteration").
  Status Check(std::string_view what) const {
    if (expired()) {
      return absl::DeadlineExceededError(kinemo::StrCat(what, ": the caller's deadline passed; stopped"));
    }
    if (stopped()) return absl::CancelledError(kinemo::StrCat(what, ": cancelled by the caller; stopped"));
    return absl::OkStatus();
  }
  Clock::time_point deadline() const { return deadline_; }

 private:
  const Clock::time_point deadline_ = Clock::time_point::max();
  const std::function<bool()> probe_;
  mutable std::atomic<bool> cancelled_{false};
};

// `cancel` may be null (work that nobody can cancel).
inline Status CheckCancel(const CancelToken* cancel, std::string_view what) {
  return cancel == nullptr ? absl::OkStatus() : cancel->Check(what);
}
inline bool Stopped(const CancelToken* cancel) { return cancel != nullptr && cancel->stopped(); }

}  // namespace kinemo
