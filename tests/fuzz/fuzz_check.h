// A property a harness checks on a parser's result: when it does not hold,
// the input is a finding (the abort makes libFuzzer keep it as a crash).
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string_view>

namespace kinemo::fuzz {

[[noreturn]] inline void PropertyFailed(const char* file, int line, const char* condition, std::string_view what) {
  std::fprintf(stderr, "%s:%d: property failed: %s: %.*s\n", file, line, condition, static_cast<int>(what.size()),
               what.data());
  std::abort();
}

}  // namespace kinemo::fuzz

// `what` (a string) is evaluated only when `cond` is false.
#define KINEMO_FUZZ_CHECK(cond, what)                                         \
  do {                                                                        \
    if (!(cond)) ::kinemo::fuzz::PropertyFailed(__FILE__, __LINE__, #cond, what); \
  } while (0)
