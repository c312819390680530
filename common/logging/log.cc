#include "common/logging/log.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace kinemo::log {
namespace {

std::atomic<int> g_min_level{static_cast<int>(Level::kInfo)};
std::atomic<Format> g_format{Format::kJson};
std::mutex g_mutex;             // guards g_component and stderr writes
std::string g_component = "kinemo";

const char* LevelName(Level level) {
  switch (level) {
    case Level::kDebug: return "debug";
    case Level::kInfo: return "info";
    case Level::kWarn: return "warn";
    case Level::kError: return "error";
  }
  return "info";
}

void AppendJsonString(std::string& out, std::string_view s) {
  out.push_back('"');
  for (unsigned char c : s) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default:
        if (c < 0x20) {
          out += absl::StrFormat("\\u%04x", c);
        } else {
          out.push_back(static_cast<char>(c));
        }
    }
  }
  out.push_back('"');
}

void AppendValue(std::string& out, const Field::Value& v, Format format) {
  if (const auto* s = std::get_if<std::string>(&v)) {
    if (format == Format::kJson) {
      AppendJsonString(out, *s);
    } else if (s->find_first_of(" \"=") != std::string::npos || s->empty()) {
      AppendJsonString(out, *s);  // quoted with escapes
    } else {
      out += *s;
    }
  } else if (const auto* i = std::get_if<std::int64_t>(&v)) {
    absl::StrAppend(&out, *i);
  } else if (const auto* d = std::get_if<double>(&v)) {
    if (std::isfinite(*d)) {
      absl::StrAppend(&out, absl::StrFormat("%.6g", *d));
    } else {
      out += format == Format::kJson ? "null" : "nan";
    }
  } else if (const auto* b = std::get_if<bool>(&v)) {
    out += *b ? "true" : "false";
  }
}

std::string NowUtc() {
  const auto now = std::chrono::system_clock::now();
  const std::time_t t = std::chrono::system_clock::to_time_t(now);
  const auto ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
  return absl::StrFormat("%s.%03dZ", buf, static_cast<int>(ms));
}

}  // namespace

void Configure(Level min_level, Format format, std::string_view component) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_min_level = static_cast<int>(min_level);
  g_format = format;
  g_component = std::string(component);
}

StatusOr<Level> ParseLevel(std::string_view text) {
  if (text.empty() || text == "info") return Level::kInfo;
  if (text == "debug") return Level::kDebug;
  if (text == "warn" || text == "warning") return Level::kWarn;
  if (text == "error") return Level::kError;
  return InvalidField("server.log_level", "'", text, "' is not one of debug, info, warn, error");
}

StatusOr<Format> ParseFormat(std::string_view text) {
  if (text.empty() || text == "json") return Format::kJson;
  if (text == "text") return Format::kText;
  return InvalidField("server.log_format", "'", text, "' is not one of json, text");
}

std::string FormatLine(Level level, std::string_view event, std::initializer_list<Field> fields,
                       Format format, std::string_view component, std::string_view timestamp) {
  std::string out;
  out.reserve(128);
  if (format == Format::kJson) {
    out += "{\"ts\":";
    AppendJsonString(out, timestamp);
    out += ",\"level\":";
    AppendJsonString(out, LevelName(level));
    out += ",\"component\":";
    AppendJsonString(out, component);
    out += ",\"event\":";
    AppendJsonString(out, event);
    for (const Field& f : fields) {
      out.push_back(',');
      AppendJsonString(out, f.key);
      out.push_back(':');
      AppendValue(out, f.value, format);
    }
    out.push_back('}');
  } else {
    out += kinemo::StrCat(timestamp, " ", LevelName(level), " ", component, " ", event);
    for (const Field& f : fields) {
      out += kinemo::StrCat(" ", f.key, "=");
      AppendValue(out, f.value, format);
    }
  }
  return out;
}

bool Enabled(Level level) { return static_cast<int>(level) >= g_min_level.load(); }

void Write(Level level, std::string_view event, std::initializer_list<Field> fields) {
  const std::string ts = NowUtc();
  std::lock_guard<std::mutex> lock(g_mutex);
  std::string line = FormatLine(level, event, fields, g_format.load(), g_component, ts);
  line.push_back('\n');
  std::fwrite(line.data(), 1, line.size(), stderr);
  std::fflush(stderr);
}

}  // namespace kinemo::log
