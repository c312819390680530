// Status and result types for kinemo's core code.
//
// Core libraries (prosody, CRF, motion graphs, tracker, Modbus link, audio,
// motion I/O) never include gRPC headers. They return absl::Status or
// absl::StatusOr<T>; common/grpc/status_mapping.h is the one place that turns
// them into grpc::Status at the RPC edge.
//
// Message convention: start with the field or location that is wrong, e.g.
//   "audio.sample_rate_hz: 0 is not a supported rate (8000..192000)"
//   "walk.bvh:12: expected OFFSET, got 'CHANNELS'"
#pragma once

#include <string>
#include <string_view>
#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"

namespace kinemo {

namespace status_internal {
// Debian 12's abseil has its own string_view type, distinct from
// std::string_view; these overloads let both flow into absl::StrCat.
template <typename T>
const T& Piece(const T& v) {
  return v;
}
inline absl::string_view Piece(std::string_view v) { return {v.data(), v.size()}; }
}  // namespace status_internal

// absl::StrCat that also accepts std::string_view arguments.
template <typename... Args>
std::string StrCat(const Args&... parts) {
  return absl::StrCat(status_internal::Piece(parts)...);
}

using Status = absl::Status;
template <typename T>
using StatusOr = absl::StatusOr<T>;

// Builds an INVALID_ARGUMENT status whose message starts with the field name.
template <typename... Args>
Status InvalidField(std::string_view field, const Args&... parts) {
  return absl::InvalidArgumentError(kinemo::StrCat(field, ": ", parts...));
}

// Prepends context ("while reading walk.bvh") to an error, keeping its code.
inline Status Annotate(const Status& s, std::string_view context) {
  if (s.ok()) return s;
  return Status(s.code(), kinemo::StrCat(context, ": ", s.message()));
}

// Puts an INVALID_ARGUMENT message that starts with a field name under the
// request field holding it: ("num_states: ...", "params") ->
// "params.num_states: ...". Other statuses pass unchanged.
inline Status UnderField(const Status& s, std::string_view parent) {
  if (s.ok() || s.code() != absl::StatusCode::kInvalidArgument) return s;
  return Status(s.code(), kinemo::StrCat(parent, ".", s.message()));
}

}  // namespace kinemo

#define KINEMO_STATUS_CONCAT_INNER_(a, b) a##b
#define KINEMO_STATUS_CONCAT_(a, b) KINEMO_STATUS_CONCAT_INNER_(a, b)

// Returns the status from the enclosing function if `expr` is not OK.
#define KINEMO_RETURN_IF_ERROR(expr)                 \
  do {                                               \
    ::absl::Status kinemo_status_ = (expr);          \
    if (!kinemo_status_.ok()) return kinemo_status_; \
  } while (0)

// KINEMO_ASSIGN_OR_RETURN(auto x, MaybeX()); declares x or returns the error.
#define KINEMO_ASSIGN_OR_RETURN(lhs, expr) \
  KINEMO_ASSIGN_OR_RETURN_IMPL_(KINEMO_STATUS_CONCAT_(kinemo_sor_, __LINE__), lhs, expr)
#define KINEMO_ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
  auto tmp = (expr);                                  \
  if (!tmp.ok()) return std::move(tmp).status();      \
  lhs = std::move(*tmp)
