// How the coordinator's gRPC adapter reports the other services: not
// configured (UNAVAILABLE naming the option), or a downstream error prefixed
// with the service it came from.
#pragma once

#include <string>
#include <string_view>

#include <grpcpp/support/status.h>

#include "absl/strings/str_cat.h"
#include "common/grpc/status_mapping.h"
#include "services/coordinator/core/live_session.h"

namespace kinemo::coordinator {

inline grpc::Status Unavailable(const char* service) { return ToGrpcStatus(NotConfigured(service)); }

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

// A callee's error about a field it was passed, renamed to the field of the
// caller's request it came from ("rig_id: no rig 'x'" -> "models.rig_id: no
// rig 'x'"); other errors unchanged.
inline grpc::Status RenameField(const grpc::Status& s, std::string_view callee_field, std::string_view field) {
  const std::string& m = s.error_message();
  if (m.size() <= callee_field.size() || m.compare(0, callee_field.size(), callee_field) != 0 ||
      m[callee_field.size()] != ':') {
    return s;
  }
  return grpc::Status(s.error_code(), std::string(field) + m.substr(callee_field.size()));
}

}  // namespace kinemo::coordinator
