// The one place where kinemo's core errors (absl::Status) become gRPC
// statuses, and back. Service adapters call ToGrpcStatus() on every error a
// core library returns; clients of other services call FromGrpcStatus().
#pragma once

#include <cstddef>
#include <string>

#include <grpcpp/support/status.h>

#include "common/status/status.h"

namespace kinemo {

// Longest message carried in a grpc::Status; longer ones are cut at a UTF-8
// boundary and end with "…".
inline constexpr std::size_t kMaxStatusMessageBytes = 1024;

// Maps the code one-to-one (absl and gRPC share the canonical codes) and caps
// the message length. OK maps to OK.
grpc::Status ToGrpcStatus(const Status& status);

// The reverse, for code that calls another service. The message is prefixed
// with `peer` (e.g. "prosody") when it is not empty.
Status FromGrpcStatus(const grpc::Status& status, const std::string& peer = "");

// Cuts `message` to at most `max_bytes` bytes without splitting a UTF-8
// sequence, appending "…" when it was cut.
std::string CapMessage(const std::string& message, std::size_t max_bytes);

}  // namespace kinemo
