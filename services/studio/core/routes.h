// The studio's HTTP routes, as plain data (no sockets): which file or body
// answers a GET, and whether a page may open the WebSocket.
//
//   GET /                 the page (static_dir/index.html)
//   GET /healthz          200 {"status":"SERVING","coordinator":"<channel state>"}
//   GET /static/<file>    the page's scripts, styles, worklet (static_dir)
//   GET /libs/<path>      the page's libraries (libs_dir: kinemo-libs.js, three.js
//                         and @pixiv/three-vrm from npm bundled; draco/)
//   GET /samples/         JSON list of the sample .wav and .bvh files
//   GET /samples/<name>   one sample
//   GET /characters/      JSON list of the bundled characters (character.h)
//   GET /characters/<name> one character's GLB
//   GET /cube/ar/<kind>/<name>.webm  the AR view of an attached cube video
//                         (cube_ar.h; kind "bundled" or "uploads"): 404 until
//                         it is drawn or once removed, 400 for a malformed name
//   GET /ws               the WebSocket (studio.proto), upgrade only
// Anything else: 404; other methods than GET and HEAD: 405.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "kinemo/studio/v1/options.pb.h"
#include "services/studio/core/character.h"

namespace kinemo::studio {

struct HttpReply {
  unsigned status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;       // sent when file_path is empty
  std::string file_path;  // a file to send (absolute, inside a served folder)
  bool health = false;    // GET /healthz: the server writes the body
  bool websocket = false; // GET /ws: only an upgrade is accepted
};

struct Sample {
  std::string name;  // file name, unique among the samples
  std::string path;  // absolute path
  std::string kind;  // "wav" or "bvh"
  std::uintmax_t bytes = 0;
};

// Immutable after construction; safe to use from every I/O thread.
class Router {
 public:
  // `options` resolved (ResolveStudioOptions). Lists the samples once.
  explicit Router(const v1::StudioOptions& options);

  // The reply to `method` `target` (the request line's target, with an
  // optional query, which is ignored).
  HttpReply Route(std::string_view method, std::string_view target) const;

  const std::vector<Sample>& samples() const { return samples_; }

 private:
  HttpReply ServeFile(const std::string& root, std::string_view relative) const;
  HttpReply CubeAr(std::string_view rest) const;
  std::string static_dir_, libs_dir_, cube_dir_;
  std::vector<Sample> samples_;
  std::string samples_json_;
  CharacterLibrary characters_;  // listing only: the bridge loads them
};

// The MIME type of a file name by its extension ("application/octet-stream"
// when unknown).
std::string ContentTypeOf(std::string_view name);

// Percent-decodes a URL path; false if it holds a bad escape or a NUL.
bool DecodePath(std::string_view path, std::string* out);

// True if a page from `origin` (the Origin header; empty = not a browser)
// may open the socket of a server reached as `host` (the Host header):
// `allowed` lists origins ("*" = any); empty = same origin only.
bool OriginAllowed(std::string_view origin, std::string_view host, const std::vector<std::string>& allowed);

}  // namespace kinemo::studio
