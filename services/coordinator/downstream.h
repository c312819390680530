// How the coordinator's gRPC adapter reports the other services: not
// configured (UNAVAILABLE naming the option), or a downstream error prefixed
// with the service it came from.
#pragma once

#include <string>

#include <grpcpp/support/status.h>

#include "absl/strings/str_cat.h"
#include "common/grpc/status_mapping.h"

namespace kinemo::coordinator {

inline grpc::Status Unavailable(const char* service) {
  return grpc::Status(grpc::StatusCode::UNAVAILABLE,
                      absl::StrCat(service, ": not configured (CoordinatorOptions.services.",
                                   service, ".address)"));
}

// A downstream error, prefixed with the service it came from.
inline grpc::Status Downstream(const char* service, const grpc::Status& s) {
  static const char* kCodes[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT",
                                 "DEADLINE_EXCEEDED", "NOT_FOUND", "ALREADY_EXISTS",
                                 "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
                                 "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL",
                                 "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  const int code = static_cast<int>(s.error_code());
  std::string message = s.error_message();
  if (message.empty()) message = code >= 0 && code <= 16 ? kCodes[code] : "error";
  return grpc::Status(s.error_code(),
                      CapMessage(absl::StrCat(service, ": ", message), kMaxStatusMessageBytes));
}

}  // namespace kinemo::coordinator
