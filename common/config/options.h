// Service options: a protobuf message read from a text-proto file. Command-line
// flags only name that file and may override where the server listens:
//
//   prosody --config prosody.textproto [--config overlay.textproto ...]
//           [--host 0.0.0.0] [--port 50051] [--port-file /tmp/p]
//
// Precedence: the message's defaults (as the service sets them), then each
// file in order (a later file is merged over the earlier ones: its scalar
// fields replace theirs, its messages merge into theirs, its repeated fields
// append; e.g. deploy/config/tls/ adds `server { tls { ... } }` to the
// deployment's files), then the flags. Errors name the file, line and
// column, or the field.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <google/protobuf/message.h>

#include "common/status/status.h"
#include "kinemo/common/v1/server.pb.h"

namespace kinemo::config {

// What a service's command line says.
struct ServerCommandLine {
  std::vector<std::string> config_paths;  // --config FILE, in order (none = defaults only)
  std::optional<std::string> host;    // --host HOST (or unix:/path)
  std::optional<std::uint32_t> port;  // --port N (0 = ephemeral)
  std::string port_file;              // --port-file FILE: the bound port is written here
  std::optional<std::uint32_t> metrics_port;  // --metrics-port N: serve /metrics there (0 = ephemeral)
  std::string metrics_port_file;              // --metrics-port-file FILE: its bound port
  bool help = false;                  // --help was given; `usage` holds the text
  std::string usage;
};

// Parses a service's argv. Unknown flags and bad values are INVALID_ARGUMENT
// errors naming the flag.
StatusOr<ServerCommandLine> ParseServerCommandLine(int argc, const char* const* argv,
                                                   std::string_view service_name);

// Parses text-proto `text` into `message` (merged over what it holds).
// `source` names the text in errors ("prosody.textproto:3:7: ...").
Status ParseTextProto(std::string_view text, std::string_view source,
                      google::protobuf::Message* message);

// Reads and parses a text-proto file. Files over 4 MiB are refused.
Status LoadTextProtoFile(const std::string& path, google::protobuf::Message* message);

// The ServerOptions inside a service's options: the message itself when it is
// a ServerOptions, else its field `server`. Null if it has neither.
common::v1::ServerOptions* MutableServerOptions(google::protobuf::Message* options);

// Fills unset server options with defaults: host 127.0.0.1, 16 MiB messages,
// 5 s shutdown grace, info level, JSON logs, metrics on 127.0.0.1 when enabled.
void ApplyServerDefaults(common::v1::ServerOptions* server);

// Checks ranges and consistency; messages name the field ("server.port: ...").
Status ValidateServerOptions(const common::v1::ServerOptions& server);

// Defaults → files → flags → ApplyServerDefaults → ValidateServerOptions.
// `options` arrives holding the service's defaults.
Status LoadServiceOptions(const ServerCommandLine& command_line,
                          google::protobuf::Message* options);

// Writes `text` to `path` atomically (temporary file + rename), so a reader
// polling for the file never sees it half written.
Status WriteFileAtomically(const std::string& path, std::string_view text);

}  // namespace kinemo::config
