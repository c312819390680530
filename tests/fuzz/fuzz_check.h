// A property a harness checks on a parser's result: when it does not hold,
// the input is a finding (the abort makes libFuzzer keep it as a crash).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <initializer_list>
#include <string_view>

#include "absl/status/status.h"

namespace kinemo::fuzz {

[[noreturn]] inline void PropertyFailed(const char* file, int line, const char* condition,
                                        std::string_view what) {
  std::fprintf(stderr, "%s:%d: property failed: %s: %.*s\n", file, line, condition,
               static_cast<int>(what.size()), what.data());
  std::abort();
}

// Fails unless `status` is an error with one of `codes`: bad input gets the
// right code (never INTERNAL or UNKNOWN).
inline void CheckRefused(const absl::Status& status, std::initializer_list<absl::StatusCode> codes,
                         const char* file, int line) {
  for (absl::StatusCode code : codes) {
    if (status.code() == code) return;
  }
  PropertyFailed(file, line, "the error's code", status.ToString());
}

// The input as text.
inline std::string_view Text(const uint8_t* data, size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

}  // namespace kinemo::fuzz

// `what` (a string) is evaluated only when `cond` is false.
#define KINEMO_FUZZ_CHECK(cond, what)                                             \
  do {                                                                            \
    if (!(cond)) ::kinemo::fuzz::PropertyFailed(__FILE__, __LINE__, #cond, what); \
  } while (0)

// KINEMO_FUZZ_CHECK_REFUSED(status, absl::StatusCode::kInvalidArgument, ...)
#define KINEMO_FUZZ_CHECK_REFUSED(status, ...) \
  ::kinemo::fuzz::CheckRefused((status), {__VA_ARGS__}, __FILE__, __LINE__)
