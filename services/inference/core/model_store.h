// Versioned model files and the model store.
//
// A model version is one binary kinemo.inference.v1.ModelFile. The store
// keeps `<model_dir>/<model_id>/v<version>.kmodel`, writes atomically
// (temporary file + rename), loads by id (latest or a given version) and
// caches loaded models; loaded models are immutable and shared.
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
#include "kinemo/inference/v1/model_file.pb.h"
#include "services/inference/core/remapped_model.h"

namespace kinemo::inference {

namespace v1 = ::kinemo::inference::v1;

// Current model file format; readers refuse newer ones.
inline constexpr std::uint32_t kModelFormatVersion = 1;

// [a-z0-9_-]{1,64}.
Status ValidateModelId(std::string_view id);

// Model ↔ file message.
v1::ModelFile EncodeModel(const RemappedModel& model, const v1::ModelInfo& info);
StatusOr<RemappedModel> DecodeModel(const v1::ModelFile& file);

// Single files (the CLI's --out / --model).
Status WriteModelFile(const std::string& path, const v1::ModelFile& file);
StatusOr<v1::ModelFile> ReadModelFile(const std::string& path);

// Metadata to store with a trained model (id/version/time filled by Save).
v1::ModelInfo MakeModelInfo(const RemappedModel& model, const ModelTrainParams& params,
                            const TrainReport& report, std::uint32_t training_sequences,
                            std::string_view description);
// ModelTrainParams ↔ TrainParams (zeros in `p` take `defaults`, then the
// documented defaults).
ModelTrainParams FromProto(const v1::TrainParams& p, const v1::TrainParams& defaults);
v1::TrainParams ToProto(const ModelTrainParams& p);

// The planner's view (T, initial, state Gaussians).
v1::ModelParameters MakeModelParameters(const RemappedModel& model);

struct LoadedModel {
  v1::ModelInfo info;
  std::shared_ptr<const RemappedModel> model;
};

class ModelStore {
 public:
  // Creates the directory if needed.
  static StatusOr<std::unique_ptr<ModelStore>> Open(const std::string& dir);

  // Saves a new version of info.model_id. ALREADY_EXISTS if the id exists and
  // !overwrite. Returns the stored info (version, created_time set).
  StatusOr<v1::ModelInfo> Save(const RemappedModel& model, v1::ModelInfo info, bool overwrite);
  // version 0 = latest. NOT_FOUND for an unknown id or version.
  StatusOr<LoadedModel> Load(std::string_view model_id, std::uint32_t version);
  // Sorted by id then version.
  StatusOr<std::vector<v1::ModelInfo>> List(bool all_versions);

  const std::string& dir() const { return dir_; }

 private:
  explicit ModelStore(std::string dir) : dir_(std::move(dir)) {}
  std::vector<std::uint32_t> Versions(std::string_view model_id) const;
  std::string PathOf(std::string_view model_id, std::uint32_t version) const;
  std::string dir_;
  std::mutex mu_;
  std::map<std::pair<std::string, std::uint32_t>, LoadedModel> cache_;
};

}  // namespace kinemo::inference
