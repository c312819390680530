// Versioned model files and the model store.
//
// A model version is one binary kinemo.inference.v1.ModelFile. The store is
// the service's artifact store (common/store, docs/store.md):
//
//   <store_dir>/models/<id>/<version>/model.kmodel
//   <store_dir>/models/<id>/<version>/artifact.json   (summary: states, window, ...)
//
// Versions are committed atomically; the newest version of an id is the one
// served. The folder names are the truth: a loaded model's info carries the
// id and version it is stored under, whatever the file says. Loaded models
// are immutable, shared, and cached until their version is deleted.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "common/status/status.h"
#include "common/store/artifact_store.h"
#include "kinemo/inference/v1/model_file.pb.h"
#include "services/inference/core/remapped_model.h"

namespace kinemo::inference {

namespace v1 = ::kinemo::inference::v1;

// Current model file format; readers refuse newer ones.
inline constexpr std::uint32_t kModelFormatVersion = 1;
// The one file of a "models" artifact version.
inline constexpr std::string_view kModelFileName = "model.kmodel";

// [a-z0-9_-]{1,64}.
Status ValidateModelId(std::string_view id);

// Model ↔ file message.
v1::ModelFile EncodeModel(const RemappedModel& model, const v1::ModelInfo& info);
StatusOr<RemappedModel> DecodeModel(const v1::ModelFile& file);

// Single files (the CLI's --out / --model).
Status WriteModelFile(const std::string& path, const v1::ModelFile& file);
StatusOr<v1::ModelFile> ReadModelFile(const std::string& path);

// The artifact.json summary of a model: {"num_states", "window",
// "lookahead_steps", "num_clusters", "covariance", "training_data_s",
// "training_sequences", "training_steps", "train_s",
// "train_crf_ll_per_step", "train_hmm_ll_per_step"}.
std::string ModelSummaryJson(const v1::ModelInfo& info);

// Metadata to store with a trained model (id/version/time filled by Save).
v1::ModelInfo MakeModelInfo(const RemappedModel& model, const ModelTrainParams& params,
                            const TrainReport& report, std::uint32_t training_sequences,
                            std::string_view description);
// ModelTrainParams ↔ TrainParams (zeros in `p` take `defaults`, then the
// documented defaults).
ModelTrainParams FromProto(const v1::TrainParams& p, const v1::TrainParams& defaults);
v1::TrainParams ToProto(const ModelTrainParams& p);

// A training or evaluation sequence as the Train / Evaluate requests carry it
// (the service's FromProto is the reverse).
v1::Sequence ToProto(const PairedSequence& sequence);

// The planner's view (T, initial, state Gaussians).
v1::ModelParameters MakeModelParameters(const RemappedModel& model);

struct LoadedModel {
  v1::ModelInfo info;
  std::shared_ptr<const RemappedModel> model;
};

class ModelStore {
 public:
  // Opens the artifact store at `root` (created if needed); `field` names the
  // option in errors. Models of the layout before the artifact store
  // (`<root>/<id>/v<N>.kmodel`) whose id the store lacks are imported once,
  // in version order.
  static StatusOr<std::unique_ptr<ModelStore>> Open(const std::string& root,
                                                    std::string_view field = "store_dir");

  // Copies the models of a read-only seed store that this one lacks, and
  // refreshes those it took from an older seed (ArtifactStore::ImportSeed).
  // A missing seed imports nothing.
  StatusOr<std::vector<store::ArtifactMeta>> ImportSeed(const std::string& seed_root);

  // Saves a new version of info.model_id. ALREADY_EXISTS if the id exists and
  // !overwrite. Returns the stored info (version set).
  StatusOr<v1::ModelInfo> Save(const RemappedModel& model, v1::ModelInfo info, bool overwrite);
  // Validates a pushed draft that holds model.kmodel (decoded and checked;
  // errors are INVALID_ARGUMENT naming `file_field`), sets the file's
  // model_id to the draft's id and commits it as the next version.
  // `description` empty = the file's own.
  StatusOr<LoadedModel> CommitPushed(store::Draft draft, std::string_view file_field, bool overwrite,
                                     std::string_view description,
                                     std::vector<store::ArtifactRef> depends_on);
  // version 0 = latest. NOT_FOUND for an unknown id or version.
  StatusOr<LoadedModel> Load(std::string_view model_id, std::uint32_t version);
  // Sorted by id then version.
  StatusOr<std::vector<v1::ModelInfo>> List(bool all_versions);
  // The store's records of the models (id "" = every id).
  StatusOr<std::vector<store::ArtifactMeta>> ListArtifacts(std::string_view model_id, bool all_versions) const;
  // Removes one version (0 = every version) and drops it from the cache.
  StatusOr<std::vector<store::ArtifactMeta>> Delete(std::string_view model_id, std::uint32_t version);

  const std::string& root() const { return store_->root(); }
  // The artifact store under the models (drafts of pushes are staged in it).
  store::ArtifactStore& artifacts() { return *store_; }

 private:
  explicit ModelStore(std::unique_ptr<store::ArtifactStore> store) : store_(std::move(store)) {}
  // Reads, decodes and caches one committed version.
  StatusOr<LoadedModel> LoadVersion(const store::ArtifactMeta& meta);
  Status ImportLegacy();
  std::unique_ptr<store::ArtifactStore> store_;
  std::mutex mu_;  // guards cache_
  std::map<std::pair<std::string, std::uint32_t>, LoadedModel> cache_;
};

}  // namespace kinemo::inference
