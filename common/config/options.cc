#include "common/config/options.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/logging/log.h"

namespace kinemo::config {
namespace {

constexpr std::size_t kMaxConfigBytes = 4u << 20;
constexpr std::uint32_t kDefaultMaxMessageBytes = 16u << 20;
constexpr std::uint32_t kMaxMaxMessageBytes = 1u << 30;
constexpr double kDefaultShutdownGraceS = 5.0;
constexpr double kMaxShutdownGraceS = 300.0;

class CollectErrors : public google::protobuf::io::ErrorCollector {
 public:
  explicit CollectErrors(std::string_view source) : source_(source) {}
  void AddError(int line, google::protobuf::io::ColumnNumber column,
                const std::string& message) override {
    errors_.push_back(kinemo::StrCat(source_, ":", line + 1, ":", column + 1, ": ", message));
  }
  void AddWarning(int line, google::protobuf::io::ColumnNumber column,
                  const std::string& message) override {
    log::Warn("config_warning", {{"source", source_},
                                 {"line", line + 1},
                                 {"column", static_cast<int>(column) + 1},
                                 {"message", message}});
  }
  const std::vector<std::string>& errors() const { return errors_; }

 private:
  std::string source_;
  std::vector<std::string> errors_;
};

Status CheckReadable(const std::string& path, std::string_view field) {
  if (access(path.c_str(), R_OK) != 0) {
    return InvalidField(field, "cannot read '", path, "'");
  }
  return absl::OkStatus();
}

}  // namespace

StatusOr<ServerCommandLine> ParseServerCommandLine(int argc, const char* const* argv,
                                                   std::string_view service_name) {
  ServerCommandLine out;
  CLI::App app{kinemo::StrCat("kinemo ", service_name, " service"), std::string(service_name)};
  std::string host;
  std::uint32_t port = 0;
  app.add_option("--config", out.config_paths,
                 "Options file (text proto); repeat to merge later files over earlier ones")
      ->check(CLI::ExistingFile);
  auto* host_opt = app.add_option("--host", host, "Override server.host (or unix:/path)");
  auto* port_opt =
      app.add_option("--port", port, "Override server.port (0 = ephemeral)")
          ->check(CLI::Range(0u, 65535u));
  app.add_option("--port-file", out.port_file, "Write the bound port to this file when serving");
  std::uint32_t metrics_port = 0;
  auto* metrics_port_opt =
      app.add_option("--metrics-port", metrics_port,
                     "Serve Prometheus GET /metrics on this port (0 = ephemeral); sets server.metrics")
          ->check(CLI::Range(0u, 65535u));
  app.add_option("--metrics-port-file", out.metrics_port_file,
                 "Write the bound /metrics port to this file when serving");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp&) {
    out.help = true;
    out.usage = app.help();
    return out;
  } catch (const CLI::ParseError& e) {
    return absl::InvalidArgumentError(kinemo::StrCat("command line: ", e.what()));
  }
  if (host_opt->count() > 0) out.host = host;
  if (port_opt->count() > 0) out.port = port;
  if (metrics_port_opt->count() > 0) out.metrics_port = metrics_port;
  return out;
}

Status ParseTextProto(std::string_view text, std::string_view source,
                      google::protobuf::Message* message) {
  google::protobuf::TextFormat::Parser parser;
  CollectErrors errors(source);
  parser.RecordErrorsTo(&errors);
  google::protobuf::Message* scratch = message->New();
  scratch->CopyFrom(*message);
  const bool ok = parser.MergeFromString(std::string(text), scratch);
  if (!ok || !errors.errors().empty()) {
    delete scratch;
    if (errors.errors().empty()) return absl::InvalidArgumentError(kinemo::StrCat(source, ": parse error"));
    return absl::InvalidArgumentError(absl::StrJoin(errors.errors(), "; "));
  }
  message->CopyFrom(*scratch);  // only a fully parsed file changes the options
  delete scratch;
  return absl::OkStatus();
}

Status LoadTextProtoFile(const std::string& path, google::protobuf::Message* message) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(kinemo::StrCat(path, ": cannot open options file"));
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) return absl::InvalidArgumentError(kinemo::StrCat(path, ": cannot read"));
  if (static_cast<std::size_t>(size) > kMaxConfigBytes) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": ", size, " bytes exceeds the ",
                                                   kMaxConfigBytes, "-byte limit for options"));
  }
  in.seekg(0);
  std::string text(static_cast<std::size_t>(size), '\0');
  in.read(text.data(), size);
  if (!in) return absl::InvalidArgumentError(kinemo::StrCat(path, ": read failed"));
  return ParseTextProto(text, path, message);
}

common::v1::ServerOptions* MutableServerOptions(google::protobuf::Message* options) {
  if (auto* direct = dynamic_cast<common::v1::ServerOptions*>(options)) return direct;
  const auto* field = options->GetDescriptor()->FindFieldByName("server");
  if (field == nullptr || field->message_type() == nullptr ||
      field->message_type() != common::v1::ServerOptions::descriptor() || field->is_repeated()) {
    return nullptr;
  }
  return dynamic_cast<common::v1::ServerOptions*>(
      options->GetReflection()->MutableMessage(options, field));
}

void ApplyServerDefaults(common::v1::ServerOptions* server) {
  if (server->host().empty()) server->set_host("127.0.0.1");
  if (server->max_message_bytes() == 0) server->set_max_message_bytes(kDefaultMaxMessageBytes);
  if (server->shutdown_grace_s() == 0) server->set_shutdown_grace_s(kDefaultShutdownGraceS);
  if (server->log_level().empty()) server->set_log_level("info");
  if (server->log_format().empty()) server->set_log_format("json");
  if (server->metrics().enabled() && server->metrics().host().empty()) {
    server->mutable_metrics()->set_host("127.0.0.1");
  }
}

namespace {

// TLS files under `prefix` ("server.tls"): cert_file and key_file together
// (required when `required`), client_ca_file only with them, all readable.
Status CheckTlsFiles(const common::v1::TlsOptions& tls, std::string_view prefix, bool required) {
  const bool has_cert = !tls.cert_file().empty();
  const bool has_key = !tls.key_file().empty();
  if (has_cert != has_key || (required && !has_cert)) {
    return InvalidField(kinemo::StrCat(prefix, has_cert ? ".key_file" : ".cert_file"),
                        "TLS needs both cert_file and key_file");
  }
  if (!tls.client_ca_file().empty() && !has_cert) {
    return InvalidField(kinemo::StrCat(prefix, ".client_ca_file"), "mutual TLS needs cert_file and key_file as well");
  }
  if (has_cert) KINEMO_RETURN_IF_ERROR(CheckReadable(tls.cert_file(), kinemo::StrCat(prefix, ".cert_file")));
  if (has_key) KINEMO_RETURN_IF_ERROR(CheckReadable(tls.key_file(), kinemo::StrCat(prefix, ".key_file")));
  if (!tls.client_ca_file().empty()) {
    KINEMO_RETURN_IF_ERROR(CheckReadable(tls.client_ca_file(), kinemo::StrCat(prefix, ".client_ca_file")));
  }
  return absl::OkStatus();
}

}  // namespace

Status ValidateServerOptions(const common::v1::ServerOptions& server) {
  const std::string& host = server.host();
  if (host.empty()) return InvalidField("server.host", "must not be empty");
  if (host.rfind("unix:", 0) == 0) {
    const std::string path = host.substr(5);
    if (path.empty()) return InvalidField("server.host", "unix: needs a socket path");
    if (path.size() > 100) return InvalidField("server.host", "unix socket path longer than 100 bytes");
  } else if (host.find_first_of(" \t/") != std::string::npos) {
    return InvalidField("server.host", "'", host, "' is not a host name or IP address");
  }
  if (server.port() > 65535) return InvalidField("server.port", server.port(), " is above 65535");
  if (server.max_message_bytes() > kMaxMaxMessageBytes) {
    return InvalidField("server.max_message_bytes", server.max_message_bytes(),
                        " exceeds the limit of ", kMaxMaxMessageBytes);
  }
  if (server.max_message_bytes() != 0 && server.max_message_bytes() < 1024) {
    return InvalidField("server.max_message_bytes", server.max_message_bytes(),
                        " is below the minimum of 1024");
  }
  const double grace = server.shutdown_grace_s();
  if (!std::isfinite(grace) || grace < 0 || grace > kMaxShutdownGraceS) {
    return InvalidField("server.shutdown_grace_s", grace, " is outside [0, ", kMaxShutdownGraceS, "]");
  }
  if (server.has_metrics()) {
    const auto& metrics = server.metrics();
    if (metrics.port() > 65535) return InvalidField("server.metrics.port", metrics.port(), " is above 65535");
    if (metrics.host().rfind("unix:", 0) == 0 || metrics.host().find_first_of(" \t/") != std::string::npos) {
      return InvalidField("server.metrics.host", "'", metrics.host(), "' is not a host name or IP address");
    }
    if (metrics.enabled() && metrics.port() != 0 && metrics.port() == server.port()) {
      return InvalidField("server.metrics.port", metrics.port(), " is server.port too");
    }
  }
  KINEMO_RETURN_IF_ERROR(log::ParseLevel(server.log_level()).status());
  KINEMO_RETURN_IF_ERROR(log::ParseFormat(server.log_format()).status());
  if (server.has_tls()) KINEMO_RETURN_IF_ERROR(CheckTlsFiles(server.tls(), "server.tls", false));
  if (server.metrics().has_tls()) {
    KINEMO_RETURN_IF_ERROR(CheckTlsFiles(server.metrics().tls(), "server.metrics.tls", true));
  }
  if (!server.metrics().bearer_token_file().empty()) {
    KINEMO_RETURN_IF_ERROR(
        CheckReadable(server.metrics().bearer_token_file(), "server.metrics.bearer_token_file"));
  }
  return absl::OkStatus();
}

Status LoadServiceOptions(const ServerCommandLine& command_line,
                          google::protobuf::Message* options) {
  if (MutableServerOptions(options) == nullptr) {
    return absl::InternalError(kinemo::StrCat(options->GetDescriptor()->full_name(),
                                            " has no `server` field of type ServerOptions"));
  }
  for (const std::string& path : command_line.config_paths) {
    KINEMO_RETURN_IF_ERROR(LoadTextProtoFile(path, options));
  }
  common::v1::ServerOptions* server = MutableServerOptions(options);
  if (command_line.host) server->set_host(*command_line.host);
  if (command_line.port) server->set_port(*command_line.port);
  if (command_line.metrics_port) {
    server->mutable_metrics()->set_enabled(true);
    server->mutable_metrics()->set_port(*command_line.metrics_port);
  }
  ApplyServerDefaults(server);
  return ValidateServerOptions(*server);
}

Status WriteFileAtomically(const std::string& path, std::string_view text) {
  const std::string tmp = kinemo::StrCat(path, ".tmp.", getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return absl::PermissionDeniedError(kinemo::StrCat(path, ": cannot create"));
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    if (!out) return absl::DataLossError(kinemo::StrCat(path, ": write failed"));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return absl::PermissionDeniedError(kinemo::StrCat(path, ": cannot rename into place"));
  }
  return absl::OkStatus();
}

}  // namespace kinemo::config
