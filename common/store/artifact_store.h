// The artifact store: one home for everything kinemo builds offline
// (inference models, motion libraries, controllers, gesture and locomotion
// graphs, cube models), laid out like a model server's base path:
//
//   <root>/<kind>/<id>/<version>/          version = 1, 2, ... (decimal)
//   <root>/<kind>/<id>/<version>/artifact.json   what the version is (below)
//   <root>/<kind>/<id>/<version>/<files>         the artifact's own files
//   <root>/.staging/                              drafts being written
//
// A version is immutable once committed: its files are written into a draft
// folder under .staging, flushed, and the folder is renamed into place (a
// POSIX rename is atomic), so a reader or a restarted service sees a version
// whole or not at all. Drafts left by a crash are removed by Open. The newest
// version of an id is the one served; older ones stay until deleted.
//
// artifact.json:
//   {"kind": "controllers", "id": "bundled", "version": 2,
//    "created_unix_ms": 1795000000000, "description": "...",
//    "files": [{"name": "controller.kctrl", "size_bytes": 123}],
//    "depends_on": [{"kind": "libraries", "id": "bundled", "version": 1}],
//    "summary": {...kind-specific...}}
//
// Plain C++ (no gRPC): services map it to their RPCs. Thread-safe.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::store {

// Kinds (folder names under the root).
inline constexpr std::string_view kModels = "models";
inline constexpr std::string_view kLibraries = "libraries";
inline constexpr std::string_view kControllers = "controllers";
inline constexpr std::string_view kGestureGraphs = "gesture_graphs";
inline constexpr std::string_view kLocomotionGraphs = "locomotion_graphs";
inline constexpr std::string_view kCubes = "cubes";
inline constexpr std::string_view kRigs = "rigs";

// Ids and kinds: [a-z0-9_-]{1,64}. INVALID_ARGUMENT naming `field`.
Status ValidateId(std::string_view id, std::string_view field);
bool IsValidId(std::string_view id);
// File names inside a version: [A-Za-z0-9._-]{1,128}, not starting with '.',
// optionally in sub-folders ("clips/a.bvh"; no "..", no absolute paths), and
// not "artifact.json". INVALID_ARGUMENT naming `field`.
Status ValidateFileName(std::string_view name, std::string_view field);

struct ArtifactRef {
  std::string kind, id;
  std::uint32_t version = 0;
  bool operator==(const ArtifactRef&) const = default;
};

struct ArtifactFile {
  std::string name;
  std::uint64_t size_bytes = 0;
};

struct ArtifactMeta {
  std::string kind, id;
  std::uint32_t version = 0;
  std::int64_t created_unix_ms = 0;
  std::string description;
  std::vector<ArtifactFile> files;       // sorted by name
  std::vector<ArtifactRef> depends_on;   // e.g. a controller's library
  std::string summary_json = "{}";       // kind-specific JSON object
  // Imported from a seed store (ImportSeed), not pushed: a newer seed may
  // replace it. artifact.json "seeded": true.
  bool seeded = false;
  std::uint64_t size_bytes() const;
  ArtifactRef ref() const { return {kind, id, version}; }
};

// "controllers/bundled/2".
std::string RefString(const ArtifactRef& ref);

class ArtifactStore;

// A version being written. Files go into a private staging folder; Commit
// makes it a version; destroying an uncommitted draft removes the folder.
class Draft {
 public:
  Draft(Draft&&) noexcept;
  Draft& operator=(Draft&&) noexcept;
  Draft(const Draft&) = delete;
  Draft& operator=(const Draft&) = delete;
  ~Draft();

  const std::string& kind() const { return kind_; }
  const std::string& id() const { return id_; }
  // The staging folder (absolute).
  const std::string& dir() const { return dir_; }
  // Where file `name` goes (parent folders are created by WriteFile /
  // CopyFile / Append; a caller writing it itself must create them).
  StatusOr<std::string> PathFor(std::string_view name) const;
  Status WriteFile(std::string_view name, std::string_view bytes);
  // Copies a file from outside the store.
  Status CopyFile(std::string_view name, const std::string& source_path);
  // Appends to a file (for chunked uploads), creating it on first use.
  Status Append(std::string_view name, std::string_view bytes);
  // Bytes written so far over every file.
  std::uint64_t bytes_written() const;

 private:
  friend class ArtifactStore;
  Draft() = default;
  std::string kind_, id_, dir_;
};

class ArtifactStore {
 public:
  // Creates `root` (and parents) if needed and removes stale drafts.
  // FAILED_PRECONDITION naming `field` when it cannot be created or written.
  static StatusOr<std::unique_ptr<ArtifactStore>> Open(const std::string& root,
                                                       std::string_view field = "store_dir");

  const std::string& root() const { return root_; }

  StatusOr<Draft> Begin(std::string_view kind, std::string_view id);
  // Makes the draft the next version of its id and returns its metadata
  // (version, created time and file list filled in). ALREADY_EXISTS naming
  // `id` when the id has a version and !overwrite. `meta`'s kind, id,
  // version, created time and files are ignored.
  StatusOr<ArtifactMeta> Commit(Draft draft, ArtifactMeta meta, bool overwrite);

  // Version 0 = the newest. NOT_FOUND naming `id` / `version`.
  StatusOr<ArtifactMeta> Get(std::string_view kind, std::string_view id,
                             std::uint32_t version = 0) const;
  // The folder of a committed version (absolute).
  std::string Dir(const ArtifactRef& ref) const;
  std::string FilePath(const ArtifactRef& ref, std::string_view name) const;
  // Sorted by kind, id, version. kind "" = every kind; id "" = every id;
  // !all_versions = the newest version of each id only. Folders that are not
  // valid versions (no readable artifact.json) are skipped.
  StatusOr<std::vector<ArtifactMeta>> List(std::string_view kind, std::string_view id = "",
                                           bool all_versions = false) const;
  // Removes one version (or every version when version == 0) and returns
  // what was removed. NOT_FOUND when there is nothing to remove.
  StatusOr<std::vector<ArtifactMeta>> Delete(std::string_view kind, std::string_view id,
                                             std::uint32_t version);
  // Brings in the seed store at `seed_root` (the bundled models of this
  // build), for each id of `kind` in it:
  // - an id this store lacks: the seed's newest version, under the same
  //   version number (keeping its metadata, so references between artifacts
  //   hold), marked seeded;
  // - an id whose newest version here came from a seed, when the seed's
  //   newest differs (created time, files or version; a kinemo upgrade
  //   rebuilt the seed): a higher seed version is added, the same version is
  //   replaced. A version without the mark counts as seeded when it has the
  //   seed's version and description (stores written before the mark).
  // - anything else (a version someone pushed) stays as it is.
  // Returns what was imported. A missing seed folder imports nothing.
  StatusOr<std::vector<ArtifactMeta>> ImportSeed(const std::string& seed_root, std::string_view kind);

 private:
  explicit ArtifactStore(std::string root) : root_(std::move(root)) {}
  std::vector<std::uint32_t> Versions(std::string_view kind, std::string_view id) const;
  // keep_version != 0: commit under that version (which must be absent).
  StatusOr<ArtifactMeta> CommitImpl(Draft draft, ArtifactMeta meta, bool overwrite, std::uint32_t keep_version);
  // Writes artifact.json, flushes and renames the draft into place (mu_ held).
  StatusOr<ArtifactMeta> Place(Draft draft, ArtifactMeta meta);
  std::string root_;
  mutable std::mutex mu_;  // serialises commits and deletes
};

// artifact.json <-> ArtifactMeta (exposed for tests and tools).
std::string MetaToJson(const ArtifactMeta& meta);
StatusOr<ArtifactMeta> MetaFromJson(std::string_view json, std::string_view source);

}  // namespace kinemo::store
