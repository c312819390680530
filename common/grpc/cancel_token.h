// The CancelToken (common/status/cancel.h) of a server call: the caller's
// remaining deadline and the call's cancellation, for core code that runs
// long work on the call's behalf. The token must not outlive the call (its
// probe reads the call's context).
#pragma once

#include <chrono>
#include <memory>

#include <grpcpp/server_context.h>

#include "common/status/cancel.h"

namespace kinemo {

// The steady-clock instant of a gRPC deadline (system clock; max = none).
inline CancelToken::Clock::time_point SteadyDeadline(std::chrono::system_clock::time_point deadline) {
  if (deadline >= std::chrono::system_clock::time_point::max() - std::chrono::hours(24 * 365)) {
    return CancelToken::Clock::time_point::max();
  }
  const auto left = deadline - std::chrono::system_clock::now();
  return CancelToken::Clock::now() + std::chrono::duration_cast<CancelToken::Clock::duration>(left);
}

inline std::unique_ptr<CancelToken> CallCancelToken(const grpc::ServerContextBase& context) {
  return std::make_unique<CancelToken>(SteadyDeadline(context.deadline()),
                                       [&context] { return context.IsCancelled(); });
}

}  // namespace kinemo
