// Typed, range-checked reads of JSON object members (nlohmann::json) for
// parsers of outside input. nlohmann's get<int>() / value(key, int) cast a
// JSON float to the integer type, which is undefined behaviour when the value
// is out of range (found by the fuzzers, tests/fuzz); these never cast
// unchecked, and their errors are INVALID_ARGUMENT naming the member:
//   "<prefix><key>: must be an integer in 1..32, got 7.5e+60"
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>

#include "common/status/status.h"

namespace kinemo {

namespace json_internal {
// A value as quoted in a message: its JSON text, shortened.
inline std::string Shown(const nlohmann::json& v) {
  std::string text = v.dump();
  if (text.size() > 40) text = text.substr(0, 40) + "...";
  return text;
}
}  // namespace json_internal

// The member `key` of object `j` as an integer in [lo, hi]; `fallback` when
// absent (std::nullopt: the member is required). JSON floats, even integral
// ones, are refused: writers of these files write integers.
template <typename T>
StatusOr<T> JsonInteger(const nlohmann::json& j, const char* key, std::optional<T> fallback,
                        std::string_view prefix, T lo = std::numeric_limits<T>::min(),
                        T hi = std::numeric_limits<T>::max()) {
  static_assert(std::is_integral_v<T> && !std::is_same_v<T, bool> && sizeof(T) >= 2 &&
                sizeof(T) <= 8);
  const auto it = j.find(key);
  if (it == j.end()) {
    if (fallback) return *fallback;
    return InvalidField(kinemo::StrCat(prefix, key), "missing");
  }
  // Every 64-bit value, signed or not, fits in 128 bits: one comparison.
  using Wide = __int128;
  bool ok = false;
  Wide v = 0;
  if (it->is_number_unsigned()) {
    v = static_cast<Wide>(it->template get<std::uint64_t>());
    ok = true;
  } else if (it->is_number_integer()) {
    v = static_cast<Wide>(it->template get<std::int64_t>());
    ok = true;
  }
  ok = ok && v >= static_cast<Wide>(lo) && v <= static_cast<Wide>(hi);
  if (!ok)
    return InvalidField(kinemo::StrCat(prefix, key), "must be an integer in ", lo, "..", hi,
                        ", got ", json_internal::Shown(*it));
  return static_cast<T>(v);
}

// The member `key` of object `j` as a finite number (integers accepted);
// `fallback` when absent (std::nullopt: required).
inline StatusOr<double> JsonNumber(const nlohmann::json& j, const char* key,
                                   std::optional<double> fallback, std::string_view prefix) {
  const auto it = j.find(key);
  if (it == j.end()) {
    if (fallback) return *fallback;
    return InvalidField(kinemo::StrCat(prefix, key), "missing");
  }
  if (!it->is_number() || !std::isfinite(it->template get<double>())) {
    return InvalidField(kinemo::StrCat(prefix, key), "must be a finite number, got ",
                        json_internal::Shown(*it));
  }
  return it->template get<double>();
}

}  // namespace kinemo
