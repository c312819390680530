// The studio's options (options.h).
#include "services/studio/core/options.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

#include "services/studio/core/auth.h"

namespace kinemo::studio {
namespace {

namespace fs = std::filesystem;

bool IsDir(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}

// The first of `candidates` that is a folder holding `marker`, or "".
std::string FirstWith(const std::vector<fs::path>& candidates, const std::string& marker) {
  std::error_code ec;
  for (const fs::path& p : candidates) {
    if (!p.empty() && fs::exists(p / marker, ec)) return fs::weakly_canonical(p, ec).string();
  }
  return "";
}

// Characters a token may hold: it travels in a cookie, a header and a URL.
bool TokenCharsOk(const std::string& token) {
  for (unsigned char c : token) {
    if (!std::isalnum(c) && c != '-' && c != '_' && c != '.' && c != '~') return false;
  }
  return true;
}

Status ResolveAuth(v1::StudioOptions* options) {
  auto* auth = options->mutable_auth();
  if (auth->token().empty() && !auth->token_file().empty()) {
    std::ifstream in(auth->token_file());
    if (!in) return InvalidField("auth.token_file", "\"", auth->token_file(), "\" cannot be read");
    std::ostringstream text;
    text << in.rdbuf();
    std::string token = text.str();
    const auto not_space = [](unsigned char c) { return !std::isspace(c); };
    token.erase(token.begin(), std::find_if(token.begin(), token.end(), not_space));
    token.erase(std::find_if(token.rbegin(), token.rend(), not_space).base(), token.end());
    if (token.empty()) return InvalidField("auth.token_file", "\"", auth->token_file(), "\" is empty");
    if (!TokenCharsOk(token) || token.size() < 16 || token.size() > 512) {
      return InvalidField("auth.token_file", "\"", auth->token_file(),
                          "\" must hold 16 to 512 characters of A-Z a-z 0-9 - _ . ~");
    }
    auth->set_token(token);
  } else if (!auth->token().empty()) {
    if (!TokenCharsOk(auth->token()) || auth->token().size() < 16 || auth->token().size() > 512) {
      return InvalidField("auth.token", "must be 16 to 512 characters of A-Z a-z 0-9 - _ . ~");
    }
  } else if (IsLoopbackHost(options->server().host())) {
    auth->set_token(NewToken());
  } else {
    return InvalidField("auth.token", "the studio listens on \"", options->server().host(),
                        "\", not loopback: set auth.token or auth.token_file (a secret of 16 or more "
                        "characters the page and clients present), or listen on 127.0.0.1");
  }
  if (auth->max_failures_per_minute() == 0) auth->set_max_failures_per_minute(10);
  if (auth->max_failures_per_minute() > 10000) {
    return InvalidField("auth.max_failures_per_minute", auth->max_failures_per_minute(), " is outside [1, 10000]");
  }
  return absl::OkStatus();
}

// A folder of bundled files: given, it must be a folder; empty, the first of
// share/kinemo/<name> beside the binary (bin/.., bin/../..) and the source
// tree's tests/data/<name> that holds `marker`, else "".
Status ResolveBundledDir(const char* field, const fs::path& bin, const fs::path& src, const std::string& name,
                         const std::string& marker, std::string* dir) {
  if (dir->empty()) {
    *dir = FirstWith({bin.parent_path() / "share/kinemo" / name,
                      bin.parent_path().parent_path() / "share/kinemo" / name,
                      src.empty() ? fs::path() : src / "tests/data" / name},
                     marker);
  } else if (!IsDir(*dir)) {
    return InvalidField(field, "\"", *dir, "\" is not a folder");
  }
  return absl::OkStatus();
}

}  // namespace

void SetStudioDefaults(v1::StudioOptions* options) { options->mutable_server()->set_port(kDefaultPort); }

Status ResolveStudioOptions(const std::string& binary_path, const std::string& source_dir,
                            v1::StudioOptions* options) {
  const auto& tls = options->server().tls();
  if (tls.cert_file().empty() != tls.key_file().empty()) {
    return InvalidField(tls.cert_file().empty() ? "server.tls.cert_file" : "server.tls.key_file",
                        "HTTPS needs both server.tls.cert_file and server.tls.key_file");
  }
  if (!tls.client_ca_file().empty() && tls.cert_file().empty()) {
    return InvalidField("server.tls.client_ca_file", "needs server.tls.cert_file and key_file (HTTPS)");
  }
  if (options->server().host().empty()) options->mutable_server()->set_host("127.0.0.1");
  KINEMO_RETURN_IF_ERROR(ResolveAuth(options));
  auto* coordinator = options->mutable_coordinator();
  if (coordinator->address().empty()) coordinator->set_address("127.0.0.1:50050");
  if (coordinator->deadline_s() < 0 || coordinator->deadline_s() > 3600) {
    return InvalidField("coordinator.deadline_s", coordinator->deadline_s(), " is outside [0, 3600]");
  }
  if (coordinator->deadline_s() == 0) coordinator->set_deadline_s(10);
  if (coordinator->max_reconnect_backoff_s() < 0 || coordinator->max_reconnect_backoff_s() > 600) {
    return InvalidField("coordinator.max_reconnect_backoff_s", coordinator->max_reconnect_backoff_s(),
                        " is outside [0, 600]");
  }
  if (coordinator->max_reconnect_backoff_s() == 0) coordinator->set_max_reconnect_backoff_s(2);
  if (options->max_upload_bytes() == 0) options->set_max_upload_bytes(kDefaultMaxUploadBytes);
  if (options->max_upload_bytes() < 4096 || options->max_upload_bytes() > kMaxUploadBytesLimit) {
    return InvalidField("max_upload_bytes", options->max_upload_bytes(), " is outside [4096, ",
                        kMaxUploadBytesLimit, "]");
  }
  if (options->max_connections() == 0) options->set_max_connections(64);
  if (options->max_connections() > 10000) {
    return InvalidField("max_connections", options->max_connections(), " is outside [1, 10000]");
  }
  if (options->max_calls_per_connection() == 0) options->set_max_calls_per_connection(16);
  if (options->max_calls_per_connection() > 1024) {
    return InvalidField("max_calls_per_connection", options->max_calls_per_connection(),
                        " is outside [1, 1024]");
  }
  if (options->animate_deadline_s() < 0 || options->animate_deadline_s() > 3600) {
    return InvalidField("animate_deadline_s", options->animate_deadline_s(), " is outside [0, 3600]");
  }
  if (options->animate_deadline_s() == 0) options->set_animate_deadline_s(300);
  if (options->io_threads() == 0) options->set_io_threads(2);
  if (options->io_threads() > 64) {
    return InvalidField("io_threads", options->io_threads(), " is outside [1, 64]");
  }
  for (int i = 0; i < options->allowed_origins_size(); ++i) {
    const std::string& o = options->allowed_origins(i);
    if (o != "*" && o.rfind("http://", 0) != 0 && o.rfind("https://", 0) != 0) {
      return InvalidField(kinemo::StrCat("allowed_origins[", i, "]"), "\"", o,
                          "\" is not \"*\" or an origin like \"http://host:port\"");
    }
  }

  const fs::path bin = fs::path(binary_path).parent_path();
  const fs::path src = source_dir.empty() ? fs::path() : fs::path(source_dir);
  if (options->static_dir().empty()) {
    options->set_static_dir(FirstWith({bin.parent_path() / "share/kinemo/studio",
                                       bin.parent_path().parent_path() / "share/kinemo/studio",
                                       src.empty() ? fs::path() : src / "services/studio/web"},
                                      "index.html"));
    if (options->static_dir().empty()) {
      return InvalidField("static_dir", "not given, and no share/kinemo/studio/index.html beside ",
                          binary_path);
    }
  } else if (!IsDir(options->static_dir())) {
    return InvalidField("static_dir", "\"", options->static_dir(), "\" is not a folder");
  }
  if (options->libs_dir().empty()) {
    options->set_libs_dir(FirstWith({bin.parent_path() / "share/kinemo/studio-libs",
                                     bin.parent_path().parent_path() / "share/kinemo/studio-libs"},
                                    "kinemo-libs.js"));
    if (options->libs_dir().empty()) {
      return InvalidField("libs_dir", "not given, and no share/kinemo/studio-libs/kinemo-libs.js beside ", binary_path,
                          " (the build's studio_libs target makes it with npm)");
    }
  } else if (!IsDir(options->libs_dir())) {
    return InvalidField("libs_dir", "\"", options->libs_dir(), "\" is not a folder");
  }
  if (options->sample_dirs().empty()) {
    for (const fs::path& p : {bin.parent_path() / "share/kinemo/samples",
                              bin.parent_path().parent_path() / "share/kinemo/samples"}) {
      if (IsDir(p)) {
        options->add_sample_dirs(p.string());
        break;
      }
    }
    if (options->sample_dirs().empty() && !src.empty()) {
      for (const char* d : {"tests/data/speech", "tests/data/paired/beat2", "tests/data/planner_gesture"}) {
        if (IsDir(src / d)) options->add_sample_dirs((src / d).string());
      }
    }
  }
  KINEMO_RETURN_IF_ERROR(ResolveBundledDir("character_dir", bin, src, "characters", "LICENSE.md",
                                           options->mutable_character_dir()));
  if (options->max_character_bytes() == 0) {
    options->set_max_character_bytes(std::min<std::uint64_t>(32u << 20, options->max_upload_bytes()));
  }
  if (options->max_character_bytes() > options->max_upload_bytes()) {
    return InvalidField("max_character_bytes", options->max_character_bytes(), " is over max_upload_bytes (",
                        options->max_upload_bytes(), ")");
  }
  KINEMO_RETURN_IF_ERROR(
      ResolveBundledDir("cube_data_dir", bin, src, "cube", "vleo.cube", options->mutable_cube_data_dir()));
  if (!options->cube_dir().empty()) {
    std::error_code ec;
    fs::create_directories(options->cube_dir(), ec);
    if (!IsDir(options->cube_dir())) {
      return InvalidField("cube_dir", "\"", options->cube_dir(), "\" is not a folder and cannot be made");
    }
    options->set_cube_dir(fs::weakly_canonical(fs::absolute(options->cube_dir()), ec).string());
    if (options->cube_data_dir().empty()) {
      return InvalidField("cube_data_dir", "not given, and no share/kinemo/cube/vleo.cube beside ", binary_path,
                          " (cube_dir needs the cube)");
    }
  }
  // The AR view's action clips (Bandai-Namco; in the runtime image beside
  // the other bundled gestures).
  if (options->cube_ar_clip_dir().empty()) {
    options->set_cube_ar_clip_dir(FirstWith({bin.parent_path() / "share/kinemo/gestures/planner_gesture",
                                             bin.parent_path().parent_path() / "share/kinemo/gestures/planner_gesture",
                                             src.empty() ? fs::path() : src / "tests/data/planner_gesture"},
                                            "dataset-1_respond_normal_001.bvh"));
  } else if (!IsDir(options->cube_ar_clip_dir())) {
    return InvalidField("cube_ar_clip_dir", "\"", options->cube_ar_clip_dir(), "\" is not a folder");
  }
  if (options->max_cube_video_bytes() == 0) {
    options->set_max_cube_video_bytes(std::min<std::uint64_t>(32u << 20, options->max_upload_bytes()));
  }
  if (options->max_cube_video_bytes() > options->max_upload_bytes()) {
    return InvalidField("max_cube_video_bytes", options->max_cube_video_bytes(), " is over max_upload_bytes (",
                        options->max_upload_bytes(), ")");
  }
  for (int i = 0; i < options->sample_dirs_size(); ++i) {
    if (!IsDir(options->sample_dirs(i))) {
      return InvalidField(kinemo::StrCat("sample_dirs[", i, "]"), "\"", options->sample_dirs(i),
                          "\" is not a folder");
    }
  }
  return absl::OkStatus();
}

}  // namespace kinemo::studio
