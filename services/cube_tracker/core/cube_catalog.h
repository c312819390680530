// The cube models a tracker serves, by id, and its default cube, kept in the
// service's artifact store (kind "cubes", docs/store.md):
//
//   <store_dir>/cubes/<id>/<version>/cube.textproto   (a CubeModel, text proto)
//
// At open, the models of the options come first and stored ones override
// them (the newest version of each id). Without a store_dir the catalog
// keeps its versions in an ephemeral store under the temp folder, removed
// when the catalog is destroyed, so that one code path serves both.
//
// The default cube (streams that name none): the stored cube whose newest
// version was configured with make_default most recently; else the options'
// default_cube_id (or the first of their cubes); else the oldest stored cube.
// At run time a make_default, or the first cube configured when there is no
// default, becomes the default; when the default is deleted (no version of
// it left, and not in the options) one is picked by the same rule.
// Thread-safe; the models handed out are immutable and shared.
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"
#include "common/store/artifact_store.h"
#include "services/cube_tracker/core/cube_model.h"

namespace kinemo::cube {

// The one file of a "cubes" artifact version.
inline constexpr std::string_view kCubeFileName = "cube.textproto";

// A model as the stored text proto (a comment line, then the CubeModel).
std::string CubeModelText(const CubeModel& model);

class CubeCatalog {
 public:
  struct Options {
    std::vector<CubeModel> cubes;   // validated, distinct names
    std::string default_cube_id;    // one of `cubes`, or "" = the first
    std::string store_dir;          // "" = ephemeral (in memory for clients)
    std::string seed_store_dir;     // "" = none
  };
  // FAILED_PRECONDITION naming store_dir when it cannot be used; a stored
  // version that cannot be read is skipped and reported in `skipped`.
  static StatusOr<std::unique_ptr<CubeCatalog>> Open(const Options& options,
                                                     std::vector<std::string>* skipped = nullptr);
  ~CubeCatalog();
  CubeCatalog(const CubeCatalog&) = delete;
  CubeCatalog& operator=(const CubeCatalog&) = delete;

  // True when there is no store_dir (versions live in a temp folder).
  bool in_memory() const { return ephemeral_; }
  store::ArtifactStore& artifacts() { return *store_; }

  struct Stored {
    std::shared_ptr<const CubeModel> model;
    bool is_default = false;
    store::ArtifactMeta meta;
  };
  // ConfigureCube: stores `model` as the next version of its name.
  // ALREADY_EXISTS naming model.cube_id when the id is served and !overwrite.
  StatusOr<Stored> Configure(const CubeModel& model, bool make_default, bool overwrite);
  // PushArtifact: the draft holds cube.textproto; it is parsed and validated
  // (INVALID_ARGUMENT naming `file_field`), its cube_id becomes the draft's
  // id, and it is committed and served.
  StatusOr<Stored> CommitPushed(store::Draft draft, std::string_view file_field, bool overwrite,
                                std::string_view description);

  // nullptr when unknown.
  std::shared_ptr<const CubeModel> Find(const std::string& id) const;
  std::shared_ptr<const CubeModel> Default() const;
  std::string default_id() const;

  StatusOr<std::vector<store::ArtifactMeta>> List(std::string_view id, bool all_versions) const;
  // Removes one version (0 = all). The id is then served from its newest
  // remaining version, else from the options, else not at all.
  StatusOr<std::vector<store::ArtifactMeta>> Delete(std::string_view id, std::uint32_t version);

 private:
  CubeCatalog() = default;
  StatusOr<Stored> CommitLocked(store::Draft draft, const CubeModel& model, bool make_default, bool overwrite,
                                std::string_view description);
  // Reads the newest stored version of `id` (NOT_FOUND when none).
  StatusOr<std::pair<CubeModel, store::ArtifactMeta>> ReadNewest(std::string_view id) const;
  void ResolveDefaultLocked();

  std::unique_ptr<store::ArtifactStore> store_;
  bool ephemeral_ = false;
  std::map<std::string, std::shared_ptr<const CubeModel>> from_options_;
  std::string options_default_;
  mutable std::mutex mu_;
  std::map<std::string, std::shared_ptr<const CubeModel>> cubes_;  // guarded by mu_
  std::string default_id_;                                         // guarded by mu_
};

}  // namespace kinemo::cube
