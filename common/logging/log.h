// Structured logging: one event per line on stderr, as JSON (default) or as
// "key=value" text. Every line has a UTC timestamp, a level, the component
// (the service name) and an event name, followed by the caller's fields:
//
//   kinemo::log::Info("listening", {{"address", "127.0.0.1:40123"}, {"port", 40123}});
//   {"ts":"2026-11-21T15:02:11.532Z","level":"info","component":"prosody",
//    "event":"listening","address":"127.0.0.1:40123","port":40123}
//
// Thread-safe; a line is written with one call so lines never interleave.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <string>
#include <string_view>
#include <variant>

#include "common/status/status.h"

namespace kinemo::log {

enum class Level { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3 };
enum class Format { kJson, kText };

// One key/value pair of a log line.
struct Field {
  using Value = std::variant<std::string, std::int64_t, double, bool>;
  Field(std::string_view k, std::string_view v) : key(k), value(std::string(v)) {}
  Field(std::string_view k, const char* v) : key(k), value(std::string(v)) {}
  Field(std::string_view k, const std::string& v) : key(k), value(v) {}
  Field(std::string_view k, int v) : key(k), value(static_cast<std::int64_t>(v)) {}
  Field(std::string_view k, unsigned v) : key(k), value(static_cast<std::int64_t>(v)) {}
  Field(std::string_view k, long v) : key(k), value(static_cast<std::int64_t>(v)) {}
  Field(std::string_view k, unsigned long v) : key(k), value(static_cast<std::int64_t>(v)) {}
  Field(std::string_view k, long long v) : key(k), value(static_cast<std::int64_t>(v)) {}
  Field(std::string_view k, double v) : key(k), value(v) {}
  Field(std::string_view k, bool v) : key(k), value(v) {}
  std::string key;
  Value value;
};

// Sets the minimum level, the format and the component name for this process.
void Configure(Level min_level, Format format, std::string_view component);

// Parses "debug" | "info" | "warn" | "error" ("" = info).
StatusOr<Level> ParseLevel(std::string_view text);
// Parses "json" | "text" ("" = json).
StatusOr<Format> ParseFormat(std::string_view text);

// Formats one line (without the trailing newline). Exposed for tests.
std::string FormatLine(Level level, std::string_view event, std::initializer_list<Field> fields,
                       Format format, std::string_view component, std::string_view timestamp);

bool Enabled(Level level);
void Write(Level level, std::string_view event, std::initializer_list<Field> fields);

inline void Debug(std::string_view event, std::initializer_list<Field> fields = {}) {
  if (Enabled(Level::kDebug)) Write(Level::kDebug, event, fields);
}
inline void Info(std::string_view event, std::initializer_list<Field> fields = {}) {
  if (Enabled(Level::kInfo)) Write(Level::kInfo, event, fields);
}
inline void Warn(std::string_view event, std::initializer_list<Field> fields = {}) {
  if (Enabled(Level::kWarn)) Write(Level::kWarn, event, fields);
}
inline void Error(std::string_view event, std::initializer_list<Field> fields = {}) {
  if (Enabled(Level::kError)) Write(Level::kError, event, fields);
}

}  // namespace kinemo::log
