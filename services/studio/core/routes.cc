// The studio's HTTP routes (routes.h).
#include "services/studio/core/routes.h"

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <system_error>

#include "common/metrics/metrics.h"
#include "services/studio/core/cube_ar.h"

namespace kinemo::studio {
namespace {

namespace fs = std::filesystem;

bool EndsWith(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

std::string Lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

HttpReply Text(unsigned status, std::string body) {
  HttpReply r;
  r.status = status;
  r.body = std::move(body);
  return r;
}

}  // namespace

std::string ContentTypeOf(std::string_view name) {
  const std::string n = Lower(name);
  struct Type {
    const char* ext;
    const char* type;
  };
  static constexpr Type kTypes[] = {
      {".html", "text/html; charset=utf-8"},     {".js", "text/javascript; charset=utf-8"},
      {".mjs", "text/javascript; charset=utf-8"}, {".css", "text/css; charset=utf-8"},
      {".json", "application/json"},              {".png", "image/png"},
      {".svg", "image/svg+xml"},                  {".ico", "image/x-icon"},
      {".wav", "audio/wav"},                      {".bvh", "text/plain; charset=utf-8"},
      {".txt", "text/plain; charset=utf-8"},      {".glb", "model/gltf-binary"},
      {".vrm", "model/gltf-binary"},              {".webm", "video/webm"},
      {".wasm", "application/wasm"},
  };
  for (const Type& t : kTypes) {
    if (EndsWith(n, t.ext)) return t.type;
  }
  return "application/octet-stream";
}

bool DecodePath(std::string_view path, std::string* out) {
  out->clear();
  for (std::size_t i = 0; i < path.size(); ++i) {
    char c = path[i];
    if (c == '%') {
      if (i + 2 >= path.size()) return false;
      auto hex = [](char h) -> int {
        if (h >= '0' && h <= '9') return h - '0';
        if (h >= 'a' && h <= 'f') return h - 'a' + 10;
        if (h >= 'A' && h <= 'F') return h - 'A' + 10;
        return -1;
      };
      const int hi = hex(path[i + 1]), lo = hex(path[i + 2]);
      if (hi < 0 || lo < 0) return false;
      c = static_cast<char>(hi * 16 + lo);
      i += 2;
    }
    if (c == '\0') return false;
    out->push_back(c);
  }
  return true;
}

bool OriginAllowed(std::string_view origin, std::string_view host, const std::vector<std::string>& allowed) {
  if (origin.empty()) return true;  // not a browser: no page to protect the socket from
  if (!allowed.empty()) {
    for (const std::string& a : allowed) {
      if (a == "*" || Lower(a) == Lower(origin)) return true;
    }
    return false;
  }
  // Same origin: "scheme://host[:port]" whose host[:port] is the Host header.
  const std::size_t scheme = origin.find("://");
  if (scheme == std::string_view::npos || host.empty()) return false;
  return Lower(origin.substr(scheme + 3)) == Lower(host);
}

Router::Router(const v1::StudioOptions& options)
    : static_dir_(options.static_dir()), libs_dir_(options.libs_dir()), cube_dir_(options.cube_dir()),
      characters_(options) {
  std::set<std::string> seen;
  for (const std::string& dir : options.sample_dirs()) {
    std::error_code ec;
    std::vector<Sample> found;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      if (!entry.is_regular_file(ec)) continue;
      const std::string name = entry.path().filename().string();
      const std::string lower = Lower(name);
      const std::string kind = EndsWith(lower, ".wav") ? "wav" : EndsWith(lower, ".bvh") ? "bvh" : "";
      if (kind.empty() || name.empty() || name[0] == '.' || !seen.insert(name).second) continue;
      found.push_back({name, fs::absolute(entry.path(), ec).string(), kind, entry.file_size(ec)});
    }
    std::sort(found.begin(), found.end(), [](const Sample& a, const Sample& b) { return a.name < b.name; });
    samples_.insert(samples_.end(), found.begin(), found.end());
  }
  nlohmann::json list = nlohmann::json::array();
  for (const Sample& s : samples_) {
    list.push_back({{"name", s.name}, {"kind", s.kind}, {"url", "/samples/" + s.name}, {"bytes", s.bytes}});
  }
  samples_json_ = nlohmann::json{{"samples", list}}.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

HttpReply Router::ServeFile(const std::string& root, std::string_view relative) const {
  std::string rel;
  if (!DecodePath(relative, &rel)) return Text(400, "bad path\n");
  // No parent references, hidden files or absolute parts.
  for (std::size_t start = 0; start <= rel.size();) {
    const std::size_t end = std::min(rel.find('/', start), rel.size());
    const std::string_view part(rel.data() + start, end - start);
    if (part.empty() || part[0] == '.' || part.find('\\') != std::string_view::npos) {
      return Text(404, "not found\n");
    }
    start = end + 1;
  }
  std::error_code ec;
  const fs::path base = fs::weakly_canonical(root, ec);
  const fs::path file = fs::weakly_canonical(fs::path(root) / rel, ec);
  if (ec || !fs::is_regular_file(file, ec)) return Text(404, "not found\n");
  // Symbolic links inside a served folder may point elsewhere in it, never
  // outside.
  const std::string b = base.string() + "/";
  if (file.string().rfind(b, 0) != 0) return Text(404, "not found\n");
  HttpReply r;
  r.content_type = ContentTypeOf(file.filename().string());
  r.file_path = file.string();
  return r;
}

// `rest` after "/cube/ar/": "<kind>/<name>.webm", a file of cube_dir/<kind>/
// named by CubeArTarget (its name checked: no other file can be reached).
HttpReply Router::CubeAr(std::string_view rest) const {
  std::string decoded;
  if (!DecodePath(rest, &decoded)) return Text(400, "bad path\n");
  const std::size_t slash = decoded.find('/');
  const std::string kind = decoded.substr(0, slash);
  const std::string file = slash == std::string::npos ? "" : decoded.substr(slash + 1);
  constexpr std::string_view kExt = ".webm";
  const std::string name = EndsWith(file, kExt) ? file.substr(0, file.size() - kExt.size()) : "";
  if ((kind != "bundled" && kind != "uploads") || !IsCubeArName(name)) {
    return Text(400, "bad AR video name: /cube/ar/bundled/<name>.webm or /cube/ar/uploads/<id>.webm, the name of "
                     "1 to 128 of A-Z a-z 0-9 _ -\n");
  }
  if (cube_dir_.empty()) return Text(404, "not found: the studio has no cube_dir\n");
  CubeArTarget target;
  target.kind = kind;
  target.name = name;
  std::error_code ec;
  const fs::path path = fs::path(cube_dir_) / target.path();
  if (!fs::is_regular_file(path, ec)) return Text(404, "not found: no such AR video (not drawn yet, or removed)\n");
  HttpReply r;
  r.content_type = "video/webm";
  r.file_path = path.string();
  return r;
}

HttpReply Router::Route(std::string_view method, std::string_view target) const {
  if (method != "GET" && method != "HEAD") return Text(405, "method not allowed\n");
  std::string_view path = target.substr(0, target.find('?'));
  if (path == "/" || path == "/index.html") return ServeFile(static_dir_, "index.html");
  if (path == "/healthz") {
    HttpReply r;
    r.health = true;
    r.content_type = "application/json";
    return r;
  }
  if (path == "/metrics") {
    // Prometheus' text exposition of this process (common/metrics): the
    // socket and message counters of the bridge, on the studio's own port.
    HttpReply r;
    r.content_type = "text/plain; version=0.0.4; charset=utf-8";
    r.body = metrics::TextExposition();
    return r;
  }
  if (path == "/ws") {
    HttpReply r = Text(426, "upgrade to a WebSocket (see proto/kinemo/studio/v1/studio.proto)\n");
    r.websocket = true;
    return r;
  }
  if (path == "/samples/" || path == "/samples") {
    HttpReply r;
    r.content_type = "application/json";
    r.body = samples_json_;
    return r;
  }
  if (path == "/characters/" || path == "/characters") {
    HttpReply r;
    r.content_type = "application/json";
    r.body = characters_.ListJson();
    return r;
  }
  constexpr std::string_view kStatic = "/static/", kLibs = "/libs/", kSamples = "/samples/",
                             kCharacters = "/characters/", kCubeAr = "/cube/ar/";
  if (path.rfind(kCubeAr, 0) == 0) return CubeAr(path.substr(kCubeAr.size()));
  if (path.rfind(kCharacters, 0) == 0) {
    std::string name;
    if (!DecodePath(path.substr(kCharacters.size()), &name)) return Text(400, "bad path\n");
    if (const CharacterLibrary::File* f = characters_.Find(name)) {
      HttpReply r;
      r.content_type = ContentTypeOf(f->name);
      r.file_path = f->path;
      return r;
    }
    return Text(404, "not found\n");
  }
  if (path.rfind(kStatic, 0) == 0) return ServeFile(static_dir_, path.substr(kStatic.size()));
  if (path.rfind(kLibs, 0) == 0) return ServeFile(libs_dir_, path.substr(kLibs.size()));
  if (path.rfind(kSamples, 0) == 0) {
    std::string name;
    if (!DecodePath(path.substr(kSamples.size()), &name)) return Text(400, "bad path\n");
    for (const Sample& s : samples_) {
      if (s.name == name) {
        HttpReply r;
        r.content_type = ContentTypeOf(s.name);
        r.file_path = s.path;
        return r;
      }
    }
  }
  return Text(404, "not found\n");
}

}  // namespace kinemo::studio
