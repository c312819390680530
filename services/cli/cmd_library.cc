// `kinemo library ...` and `kinemo graph ...`: the planner's stored motion
// libraries and gesture / locomotion graphs (docs/store.md), against a
// planner or a coordinator (--server, default $KINEMO_SERVER or the local
// stack).
//
//   kinemo library push DIR | MANIFEST.json | FILE.bvh... --id ID [--overwrite]
//                       [--meters-per-unit M] [--description TEXT] [--json]
//   kinemo library load --path P [--path P...] --id ID [--overwrite] [--json]
//                                              (server-side paths under library_root)
//   kinemo library ls [--all] [--json]
//   kinemo library rm ID[@VERSION]
//   kinemo graph ls [--all] [--json]  (gesture and locomotion graphs)
//   kinemo graph rm ID[@VERSION] [--kind gesture|locomotion]
//
// A push uploads the clips in chunks (no size limit but the server's
// max_artifact_bytes) with a manifest.json that keeps each clip's name, tone,
// keywords and annotation, so the stored library equals the one a local
// LoadLibrary of the same sources gives (e.g. what `kinemo controller build
// --library` used).
#include <CLI/CLI.hpp>
#include <stdlib.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "common/grpc/status_mapping.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "services/cli/artifact_commands.h"
#include "services/cli/commands.h"
#include "services/cli/proto_json.h"

namespace kinemo::cli {
namespace {
namespace cmd_library {  // this file's own helpers (the unity build puts files together)

namespace fs = std::filesystem;
using Json = nlohmann::json;

[[noreturn]] void Fail(const Status& s) { FailArtifactCommand("library", s); }

template <typename T>
T OrFail(StatusOr<T> v) {
  if (!v.ok()) Fail(v.status());
  return *std::move(v);
}

bool IsBvh(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext == ".bvh";
}

// A local file name as a name the store accepts: [A-Za-z0-9._-], not
// starting with '.'.
std::string StoreSafe(const std::string& name) {
  std::string out;
  for (char c : name) {
    const bool ok = std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-';
    out.push_back(ok ? c : '_');
  }
  if (out.empty() || out[0] == '.') out.insert(out.begin(), '_');
  return out.substr(0, 120);
}

// A scratch folder removed at exit of the command.
class ScratchDir {
 public:
  ScratchDir() {
    std::error_code ec;
    std::string pattern = (fs::temp_directory_path(ec) / "kinemo-push-XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) Fail(absl::InternalError("cannot create a temporary folder"));
    path_ = pattern;
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

struct PushFlags {
  std::vector<std::string> sources;
  std::string id, description, server = DefaultServer();
  double meters_per_unit = 0;
  bool overwrite = false, json = false;
};

// The files of a library push: each clip as clips/<name>, plus a manifest
// (written into `scratch`) listing them in the order a local load takes them,
// with their names (file stems unless the manifest says).
PushSpec LibraryPushSpec(const PushFlags& f, const std::string& scratch) {
  std::vector<fs::path> files;
  Json manifest = Json::object();
  Json entries = Json::array();
  auto add_clip = [&](const fs::path& path, Json entry) {
    if (!entry.contains("name")) entry["name"] = path.stem().string();
    files.push_back(path);
    entry["path"] = path.string();  // replaced by its pushed name below
    entries.push_back(std::move(entry));
  };
  if (f.sources.size() == 1 && fs::is_directory(f.sources[0])) {
    // Every *.bvh inside, recursively, in path order (as LoadLibrary).
    std::vector<fs::path> found;
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(f.sources[0], ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec)) {
      if (it->is_regular_file(ec) && IsBvh(it->path())) found.push_back(it->path());
    }
    std::sort(found.begin(), found.end());
    if (found.empty()) Fail(InvalidField("SOURCE", f.sources[0], ": no *.bvh files in folder"));
    for (const auto& p : found) add_clip(p, Json::object());
  } else if (f.sources.size() == 1 && fs::path(f.sources[0]).extension() == ".json") {
    std::ifstream in(f.sources[0]);
    if (!in) Fail(absl::NotFoundError(kinemo::StrCat(f.sources[0], ": cannot open")));
    std::stringstream text;
    text << in.rdbuf();
    manifest = Json::parse(text.str(), nullptr, false);
    if (manifest.is_discarded() || !manifest.is_object() || !manifest.contains("clips") ||
        !manifest["clips"].is_array()) {
      Fail(InvalidField(f.sources[0], "not a library manifest (a JSON object with a list of clips)"));
    }
    const fs::path dir = fs::path(f.sources[0]).parent_path();
    int i = 0;
    for (const auto& entry : manifest["clips"]) {
      if (!entry.is_object() || !entry.contains("path") || !entry["path"].is_string()) {
        Fail(InvalidField(kinemo::StrCat(f.sources[0], ": clips[", i, "].path"), "missing"));
      }
      fs::path p = entry["path"].get<std::string>();
      if (p.is_relative()) p = dir / p;
      add_clip(p, entry);
      ++i;
    }
  } else {
    for (const auto& s : f.sources) {
      if (!IsBvh(s)) Fail(InvalidField("SOURCE", "'", s, "': give one folder, one manifest .json or .bvh files"));
      add_clip(s, Json::object());
    }
  }
  PushSpec spec;
  spec.kind = "libraries";
  spec.id = f.id;
  spec.overwrite = f.overwrite;
  spec.description = f.description.empty() ? kinemo::StrCat("kinemo library push ", f.sources[0]) : f.description;
  std::set<std::string> used;
  for (size_t i = 0; i < files.size(); ++i) {
    std::error_code ec;
    if (!fs::is_regular_file(files[i], ec)) Fail(absl::NotFoundError(kinemo::StrCat(files[i].string(), ": no such file")));
    const std::string base = StoreSafe(files[i].stem().string());
    std::string name = kinemo::StrCat("clips/", base, ".bvh");
    for (int k = 2; used.count(name); ++k) name = kinemo::StrCat("clips/", base, "-", k, ".bvh");
    used.insert(name);
    entries[i]["path"] = name;
    spec.files.emplace_back(name, files[i].string());
  }
  manifest["clips"] = entries;
  if (f.meters_per_unit > 0) manifest["meters_per_unit"] = f.meters_per_unit;
  const std::string manifest_path = scratch + "/manifest.json";
  std::ofstream(manifest_path) << manifest.dump(1) << "\n";
  spec.files.emplace_back("manifest.json", manifest_path);
  return spec;
}

void RunPush(const PushFlags& f) {
  ScratchDir scratch;
  RunArtifactPush("library", LibraryPushSpec(f, scratch.path()), f.server, f.json);
}

struct LoadFlags {
  std::vector<std::string> paths;
  std::string id, server = DefaultServer();
  double meters_per_unit = 0, timeout_s = 600;
  bool overwrite = false, json = false;
};

void RunLoad(const LoadFlags& f) {
  planner::v1::LoadLibraryRequest req;
  req.set_library_id(f.id);
  for (const auto& p : f.paths) req.add_paths(p);
  req.set_meters_per_unit(f.meters_per_unit);
  req.set_overwrite(f.overwrite);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(static_cast<long long>(f.timeout_s * 1000)));
  planner::v1::LoadLibraryResponse resp;
  const grpc::Status s = planner::v1::PlannerService::NewStub(ServerChannel(f.server))->LoadLibrary(&ctx, req, &resp);
  if (!s.ok()) Fail(FromGrpcStatus(s, "planner"));
  for (const auto& w : resp.warnings()) std::fprintf(stderr, "kinemo library: warning: %s\n", w.c_str());
  const auto& lib = resp.library();
  if (f.json) {
    planner::v1::LibraryInfo brief = lib;
    brief.clear_skeleton();
    std::printf("%s\n", ProtoJson(brief).c_str());
    return;
  }
  std::printf("stored libraries/%s/%u: %d clips, %.1f s, %u segments, %u phrases, %.0f fps\n", lib.library_id().c_str(),
              lib.version(), lib.clips_size(), lib.duration_s(), lib.segments(), lib.phrases(), lib.frame_rate_hz());
}

}  // namespace cmd_library
}  // namespace

void RegisterLibraryCommands(CLI::App& app) {
  using namespace cmd_library;
  const std::string server_help = "Address of the planner or a coordinator (default $KINEMO_SERVER or localhost:50050)";
  CLI::App* lib = app.add_subcommand("library", "The planner's stored motion libraries: push, load, ls, rm");
  lib->require_subcommand(1);

  auto pf = std::make_shared<PushFlags>();
  CLI::App* push = lib->add_subcommand("push", "Upload a library (a folder, a manifest .json, or .bvh files)");
  push->add_option("SOURCE", pf->sources, "A folder of BVH files, a library manifest .json, or .bvh files")->required();
  push->add_option("--id", pf->id, "Id to store it under ([a-z0-9_-]{1,64})")->required();
  push->add_option("--server", pf->server, server_help);
  push->add_option("--meters-per-unit", pf->meters_per_unit, "Skeleton scale (default: manifest, else estimated)");
  push->add_option("--description", pf->description, "Free text stored with it");
  push->add_flag("--overwrite", pf->overwrite, "Store a new version when the id exists");
  push->add_flag("--json", pf->json, "Print the stored ArtifactInfo as JSON");
  push->callback([pf] { RunPush(*pf); });

  auto lf = std::make_shared<LoadFlags>();
  CLI::App* load = lib->add_subcommand("load", "Load a library from server-side paths (under the planner's library_root)");
  load->add_option("--path", lf->paths, "BVH file, folder or manifest, relative to library_root (repeatable)")->required();
  load->add_option("--id", lf->id, "Id to store it under")->required();
  load->add_option("--server", lf->server, server_help);
  load->add_option("--meters-per-unit", lf->meters_per_unit, "Skeleton scale (default: manifest, else estimated)");
  load->add_option("--timeout-s", lf->timeout_s, "Deadline (default 600)");
  load->add_flag("--overwrite", lf->overwrite, "Store a new version when the id exists");
  load->add_flag("--json", lf->json, "Print the LibraryInfo (without skeleton) as JSON");
  load->callback([lf] { RunLoad(*lf); });

  AddArtifactListAndRemove(lib, "library", {"libraries"});

  CLI::App* graph = app.add_subcommand("graph", "The planner's stored gesture and locomotion graphs: ls, rm");
  graph->require_subcommand(1);
  AddArtifactListAndRemove(graph, "graph", {"gesture_graphs", "locomotion_graphs"});
}

}  // namespace kinemo::cli
