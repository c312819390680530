#include "services/cube_tracker/core/cube_catalog.h"

#include <stdlib.h>

#include <filesystem>
#include <fstream>

#include <google/protobuf/text_format.h>
#include <nlohmann/json.hpp>

#include "common/config/options.h"

namespace kinemo::cube {
namespace {

namespace fs = std::filesystem;

std::string Summary(const CubeModel& m, bool make_default) {
  return nlohmann::json{{"dictionary", m.dictionary},
                        {"cube_size_m", m.cube_size_m},
                        {"marker_size_m", m.marker_size_m},
                        {"make_default", make_default}}
      .dump();
}

bool MadeDefault(const store::ArtifactMeta& meta) {
  const auto j = nlohmann::json::parse(meta.summary_json, nullptr, false);
  return j.is_object() && j.value("make_default", false);
}

// Parses a stored or pushed cube.textproto; its cube_id becomes `id`.
StatusOr<CubeModel> ParseStored(const std::string& path, const std::string& id) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(kinemo::StrCat("'", kCubeFileName, "' is missing"));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  cube_tracker::v1::CubeModel proto;
  KINEMO_RETURN_IF_ERROR(config::ParseTextProto(text, kCubeFileName, &proto));
  proto.set_cube_id(id);
  return CubeModelFromProto(proto);
}

}  // namespace

std::string CubeModelText(const CubeModel& model) {
  std::string text;
  google::protobuf::TextFormat::PrintToString(CubeModelToProto(model), &text);
  return "# kinemo.cube_tracker.v1.CubeModel (proto/kinemo/cube_tracker/v1/cube_tracker.proto)\n" + text;
}

StatusOr<std::unique_ptr<CubeCatalog>> CubeCatalog::Open(const Options& options, std::vector<std::string>* skipped) {
  std::unique_ptr<CubeCatalog> c(new CubeCatalog());
  std::string root = options.store_dir;
  if (root.empty()) {
    std::string pattern = (fs::temp_directory_path() / "kinemo-cubes-XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) {
      return absl::FailedPreconditionError("store_dir: empty, and no temporary folder could be made for the cubes");
    }
    root = pattern;
    c->ephemeral_ = true;
  }
  auto opened = store::ArtifactStore::Open(root, "store_dir");
  if (!opened.ok()) {
    if (c->ephemeral_) fs::remove_all(root);
    return opened.status();
  }
  c->store_ = *std::move(opened);
  for (const CubeModel& m : options.cubes) {
    c->from_options_[m.name] = std::make_shared<const CubeModel>(m);
  }
  c->options_default_ = !options.default_cube_id.empty() ? options.default_cube_id
                        : options.cubes.empty()          ? ""
                                                         : options.cubes.front().name;
  c->cubes_ = c->from_options_;
  if (!options.seed_store_dir.empty()) {
    auto seeded = c->store_->ImportSeed(options.seed_store_dir, store::kCubes);
    if (!seeded.ok()) return Annotate(seeded.status(), "seed_store_dir");
  }
  KINEMO_ASSIGN_OR_RETURN(auto stored, c->store_->List(store::kCubes));
  for (const auto& meta : stored) {
    auto m = ParseStored(c->store_->FilePath(meta.ref(), kCubeFileName), meta.id);
    if (!m.ok()) {
      if (skipped != nullptr) skipped->push_back(kinemo::StrCat(store::RefString(meta.ref()), ": ", m.status().message()));
      continue;
    }
    c->cubes_[meta.id] = std::make_shared<const CubeModel>(*std::move(m));
  }
  std::lock_guard<std::mutex> lock(c->mu_);
  c->ResolveDefaultLocked();
  return c;
}

CubeCatalog::~CubeCatalog() {
  if (ephemeral_ && store_ != nullptr) {
    std::error_code ec;
    fs::remove_all(store_->root(), ec);
  }
}

void CubeCatalog::ResolveDefaultLocked() {
  auto stored = store_->List(store::kCubes);
  std::string marked, oldest;
  std::int64_t marked_ms = -1, oldest_ms = 0;
  if (stored.ok()) {
    for (const auto& meta : *stored) {
      if (cubes_.count(meta.id) == 0) continue;  // unreadable
      if (MadeDefault(meta) && meta.created_unix_ms > marked_ms) {
        marked = meta.id;
        marked_ms = meta.created_unix_ms;
      }
      if (oldest.empty() || meta.created_unix_ms < oldest_ms) {
        oldest = meta.id;
        oldest_ms = meta.created_unix_ms;
      }
    }
  }
  if (!marked.empty()) {
    default_id_ = marked;
  } else if (!options_default_.empty() && cubes_.count(options_default_) != 0) {
    default_id_ = options_default_;
  } else if (!oldest.empty()) {
    default_id_ = oldest;
  } else {
    default_id_.clear();
  }
}

StatusOr<CubeCatalog::Stored> CubeCatalog::CommitLocked(store::Draft draft, const CubeModel& model, bool make_default,
                                                        bool overwrite, std::string_view description) {
  if (cubes_.count(model.name) != 0 && !overwrite) {
    return absl::AlreadyExistsError(
        kinemo::StrCat("'", model.name, "' is already stored (set overwrite to replace it)"));
  }
  KINEMO_RETURN_IF_ERROR(draft.WriteFile(kCubeFileName, CubeModelText(model)));
  store::ArtifactMeta meta;
  meta.description = std::string(description);
  meta.summary_json = Summary(model, make_default);
  // The in-memory check above covers the store's own (ids stored are served).
  KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta committed, store_->Commit(std::move(draft), std::move(meta), true));
  auto shared = std::make_shared<const CubeModel>(model);
  cubes_[model.name] = shared;
  if (make_default || default_id_.empty()) default_id_ = model.name;
  return Stored{shared, default_id_ == model.name, std::move(committed)};
}

StatusOr<CubeCatalog::Stored> CubeCatalog::Configure(const CubeModel& model, bool make_default, bool overwrite) {
  KINEMO_ASSIGN_OR_RETURN(store::Draft draft, store_->Begin(store::kCubes, model.name));
  std::lock_guard<std::mutex> lock(mu_);
  auto r = CommitLocked(std::move(draft), model, make_default, overwrite, "ConfigureCube");
  if (!r.ok() && r.status().code() == absl::StatusCode::kAlreadyExists) {
    return absl::AlreadyExistsError(kinemo::StrCat("model.cube_id: ", r.status().message()));
  }
  return r;
}

StatusOr<CubeCatalog::Stored> CubeCatalog::CommitPushed(store::Draft draft, std::string_view file_field, bool overwrite,
                                                        std::string_view description) {
  KINEMO_ASSIGN_OR_RETURN(std::string path, draft.PathFor(kCubeFileName));
  auto model = ParseStored(path, draft.id());
  if (!model.ok()) {
    return InvalidField(file_field, "'", kCubeFileName, "' is not a valid cube model: ", model.status().message());
  }
  std::lock_guard<std::mutex> lock(mu_);
  auto r = CommitLocked(std::move(draft), *model, false, overwrite, description);
  if (!r.ok() && r.status().code() == absl::StatusCode::kAlreadyExists) {
    return absl::AlreadyExistsError(kinemo::StrCat("header.ref.id: ", r.status().message()));
  }
  return r;
}

std::shared_ptr<const CubeModel> CubeCatalog::Find(const std::string& id) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = cubes_.find(id);
  return it == cubes_.end() ? nullptr : it->second;
}

std::shared_ptr<const CubeModel> CubeCatalog::Default() const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = cubes_.find(default_id_);
  return it == cubes_.end() ? nullptr : it->second;
}

std::string CubeCatalog::default_id() const {
  std::lock_guard<std::mutex> lock(mu_);
  return default_id_;
}

StatusOr<std::vector<store::ArtifactMeta>> CubeCatalog::List(std::string_view id, bool all_versions) const {
  return store_->List(store::kCubes, id, all_versions);
}

StatusOr<std::pair<CubeModel, store::ArtifactMeta>> CubeCatalog::ReadNewest(std::string_view id) const {
  KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta, store_->Get(store::kCubes, id));
  KINEMO_ASSIGN_OR_RETURN(CubeModel m, ParseStored(store_->FilePath(meta.ref(), kCubeFileName), meta.id));
  return std::make_pair(std::move(m), std::move(meta));
}

StatusOr<std::vector<store::ArtifactMeta>> CubeCatalog::Delete(std::string_view id, std::uint32_t version) {
  std::lock_guard<std::mutex> lock(mu_);
  KINEMO_ASSIGN_OR_RETURN(auto removed, store_->Delete(store::kCubes, id, version));
  const std::string key(id);
  if (auto newest = ReadNewest(id); newest.ok()) {
    cubes_[key] = std::make_shared<const CubeModel>(std::move(newest->first));
  } else if (auto it = from_options_.find(key); it != from_options_.end()) {
    cubes_[key] = it->second;
  } else {
    cubes_.erase(key);
  }
  if (default_id_ == key && cubes_.count(key) == 0) ResolveDefaultLocked();
  return removed;
}

}  // namespace kinemo::cube
