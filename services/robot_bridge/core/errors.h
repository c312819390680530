// Error helpers for the bridge core. (Debian's absl has its own string_view,
// so std::string_view cannot go into absl::StrCat; these take absl's.)
#pragma once

#include <string_view>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "common/status/status.h"

namespace kinemo::robot {

inline absl::string_view AV(std::string_view s) { return absl::string_view(s.data(), s.size()); }

// INVALID_ARGUMENT whose message starts with the field name.
template <typename... Args>
Status BadField(absl::string_view field, const Args&... parts) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", parts...));
}

// Prepends context to an error, keeping its code.
inline Status Context(const Status& s, absl::string_view context) {
  if (s.ok()) return s;
  return Status(s.code(), absl::StrCat(context, ": ", s.message()));
}

}  // namespace kinemo::robot
