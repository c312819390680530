#include "services/inference/core/model_store.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/config/options.h"

namespace kinemo::inference {
namespace {

namespace fs = std::filesystem;

v1::Matrix ToMatrix(const Eigen::Ref<const Eigen::MatrixXd>& m) {
  v1::Matrix out;
  out.set_rows(static_cast<std::uint32_t>(m.rows()));
  out.set_cols(static_cast<std::uint32_t>(m.cols()));
  out.mutable_values()->Reserve(static_cast<int>(m.size()));
  for (Eigen::Index r = 0; r < m.rows(); ++r)
    for (Eigen::Index c = 0; c < m.cols(); ++c) out.add_values(m(r, c));
  return out;
}

StatusOr<Eigen::MatrixXd> FromMatrix(const v1::Matrix& m, std::string_view field) {
  if (static_cast<std::uint64_t>(m.rows()) * m.cols() != static_cast<std::uint64_t>(m.values_size()))
    return InvalidField(field, m.values_size(), " values for a ", m.rows(), "x", m.cols(),
                        " matrix");
  Eigen::MatrixXd out(m.rows(), m.cols());
  for (std::uint32_t r = 0; r < m.rows(); ++r)
    for (std::uint32_t c = 0; c < m.cols(); ++c) out(r, c) = m.values(static_cast<int>(r * m.cols() + c));
  return out;
}

template <typename R>
Eigen::VectorXd ToVector(const R& repeated) {
  Eigen::VectorXd v(repeated.size());
  for (int i = 0; i < repeated.size(); ++i) v(i) = repeated.Get(i);
  return v;
}

template <typename R>
void FromVector(const Eigen::VectorXd& v, R* repeated) {
  repeated->Clear();
  for (Eigen::Index i = 0; i < v.size(); ++i) repeated->Add(v(i));
}

bool ParseVersionFile(const std::string& name, std::uint32_t* version) {
  if (name.size() < 9 || name[0] != 'v' || !name.ends_with(".kmodel")) return false;
  const std::string digits = name.substr(1, name.size() - 8);
  if (digits.empty() || !std::all_of(digits.begin(), digits.end(), ::isdigit)) return false;
  *version = static_cast<std::uint32_t>(std::stoul(digits));
  return *version > 0;
}

}  // namespace

Status ValidateModelId(std::string_view id) { return store::ValidateId(id, "model_id"); }

v1::ModelFile EncodeModel(const RemappedModel& model, const v1::ModelInfo& info) {
  v1::ModelFile f;
  f.set_format_version(kModelFormatVersion);
  *f.mutable_info() = info;
  f.mutable_info()->set_format_version(kModelFormatVersion);
  for (int d = 0; d < 3; ++d) {
    f.mutable_normalizer()->add_mean(model.normalizer().mean(d));
    f.mutable_normalizer()->add_scale(model.normalizer().scale(d));
  }
  FromVector(model.clusters().weights(), f.mutable_clusters()->mutable_weights());
  *f.mutable_clusters()->mutable_means() = ToMatrix(model.clusters().means());
  *f.mutable_clusters()->mutable_variances() = ToMatrix(model.clusters().variances());
  const GaussianHmm& h = model.hmm();
  FromVector(h.initial(), f.mutable_hmm()->mutable_initial());
  *f.mutable_hmm()->mutable_transition() = ToMatrix(h.transition());
  *f.mutable_hmm()->mutable_means() = ToMatrix(h.means());
  for (const auto& c : h.covariances()) *f.mutable_hmm()->add_covariances() = ToMatrix(c);
  f.mutable_hmm()->set_covariance(h.full_covariance() ? v1::COVARIANCE_TYPE_FULL
                                                      : v1::COVARIANCE_TYPE_DIAGONAL);
  const RemappedCrf& c = model.crf();
  f.mutable_crf()->set_window(static_cast<std::uint32_t>(c.window()));
  f.mutable_crf()->set_num_clusters(static_cast<std::uint32_t>(c.num_clusters()));
  *f.mutable_crf()->mutable_transition_weights() = ToMatrix(c.transition_weights());
  FromVector(c.initial_weights(), f.mutable_crf()->mutable_initial_weights());
  *f.mutable_crf()->mutable_observation_weights() = ToMatrix(c.observation_weights());
  f.mutable_baseline()->set_window(static_cast<std::uint32_t>(model.baseline().window()));
  *f.mutable_baseline()->mutable_means() = ToMatrix(model.baseline().means());
  *f.mutable_baseline()->mutable_variances() = ToMatrix(model.baseline().variances());
  return f;
}

StatusOr<RemappedModel> DecodeModel(const v1::ModelFile& f) {
  if (f.format_version() == 0 || f.format_version() > kModelFormatVersion)
    return InvalidField("format_version", f.format_version(), " is not supported (this build reads ≤ ",
                        kModelFormatVersion, ")");
  if (f.normalizer().mean_size() != 3 || f.normalizer().scale_size() != 3)
    return InvalidField("normalizer", "expected 3 means and 3 scales");
  InputNormalizer norm;
  for (int d = 0; d < 3; ++d) {
    norm.mean(d) = f.normalizer().mean(d);
    norm.scale(d) = f.normalizer().scale(d);
  }
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd cm, FromMatrix(f.clusters().means(), "clusters.means"));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd cv,
                          FromMatrix(f.clusters().variances(), "clusters.variances"));
  KINEMO_ASSIGN_OR_RETURN(ProsodyClusters clusters,
                          ProsodyClusters::FromParameters(ToVector(f.clusters().weights()), cm, cv));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd tr, FromMatrix(f.hmm().transition(), "hmm.transition"));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd hm, FromMatrix(f.hmm().means(), "hmm.means"));
  std::vector<Eigen::MatrixXd> covs;
  for (int i = 0; i < f.hmm().covariances_size(); ++i) {
    KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd c, FromMatrix(f.hmm().covariances(i),
                                                          kinemo::StrCat("hmm.covariances[", i, "]")));
    covs.push_back(std::move(c));
  }
  KINEMO_ASSIGN_OR_RETURN(
      GaussianHmm hmm,
      GaussianHmm::FromParameters(ToVector(f.hmm().initial()), tr, hm, std::move(covs),
                                  f.hmm().covariance() == v1::COVARIANCE_TYPE_FULL));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd w,
                          FromMatrix(f.crf().transition_weights(), "crf.transition_weights"));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd u,
                          FromMatrix(f.crf().observation_weights(), "crf.observation_weights"));
  KINEMO_ASSIGN_OR_RETURN(
      RemappedCrf crf,
      RemappedCrf::FromParameters(static_cast<int>(f.crf().window()),
                                  static_cast<int>(f.crf().num_clusters()), w,
                                  ToVector(f.crf().initial_weights()), RowMatrix(u)));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd bm, FromMatrix(f.baseline().means(), "baseline.means"));
  KINEMO_ASSIGN_OR_RETURN(Eigen::MatrixXd bv,
                          FromMatrix(f.baseline().variances(), "baseline.variances"));
  KINEMO_ASSIGN_OR_RETURN(RemappedHmmBaseline baseline,
                          RemappedHmmBaseline::FromParameters(static_cast<int>(f.baseline().window()),
                                                              hmm.num_states(), bm, bv));
  return RemappedModel::FromParts(norm, std::move(clusters), std::move(hmm), std::move(crf),
                                  std::move(baseline));
}

Status WriteModelFile(const std::string& path, const v1::ModelFile& file) {
  std::string bytes;
  if (!file.SerializeToString(&bytes)) return absl::InternalError(kinemo::StrCat(path, ": serialisation failed"));
  const fs::path p(path);
  if (p.has_parent_path()) {
    std::error_code ec;
    fs::create_directories(p.parent_path(), ec);
  }
  return config::WriteFileAtomically(path, bytes);
}

StatusOr<v1::ModelFile> ReadModelFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(kinemo::StrCat(path, ": cannot open model file"));
  std::stringstream ss;
  ss << in.rdbuf();
  v1::ModelFile f;
  if (!f.ParseFromString(ss.str()))
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": not a kinemo model file"));
  if (f.format_version() == 0 || f.format_version() > kModelFormatVersion)
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": model format version ",
                                                     f.format_version(), " is not supported"));
  return f;
}

ModelTrainParams FromProto(const v1::TrainParams& p, const v1::TrainParams& d) {
  ModelTrainParams m;
  auto pick_u = [](std::uint32_t a, std::uint32_t b, int fallback) {
    return static_cast<int>(a != 0 ? a : (b != 0 ? b : static_cast<std::uint32_t>(fallback)));
  };
  auto pick_d = [](double a, double b, double fallback) { return a != 0 ? a : (b != 0 ? b : fallback); };
  m.num_states = pick_u(p.num_states(), d.num_states(), m.num_states);
  m.window = pick_u(p.window(), d.window(), m.window);
  m.num_clusters = pick_u(p.num_clusters(), d.num_clusters(), m.num_clusters);
  const auto cov = p.covariance() != v1::COVARIANCE_TYPE_UNSPECIFIED ? p.covariance() : d.covariance();
  m.full_covariance = cov == v1::COVARIANCE_TYPE_FULL;
  m.hmm_restarts = pick_u(p.hmm_restarts(), d.hmm_restarts(), m.hmm_restarts);
  m.hmm_max_iterations = pick_u(p.hmm_max_iterations(), d.hmm_max_iterations(), m.hmm_max_iterations);
  m.hmm_tolerance = pick_d(p.hmm_tolerance(), d.hmm_tolerance(), m.hmm_tolerance);
  m.crf_l2 = pick_d(p.crf_l2(), d.crf_l2(), m.crf_l2);
  m.crf_max_iterations = pick_u(p.crf_max_iterations(), d.crf_max_iterations(), m.crf_max_iterations);
  m.crf_tolerance = pick_d(p.crf_tolerance(), d.crf_tolerance(), m.crf_tolerance);
  m.seed = p.seed() != 0 ? p.seed() : (d.seed() != 0 ? d.seed() : m.seed);
  m.variance_floor = pick_d(p.variance_floor(), d.variance_floor(), m.variance_floor);
  return m;
}

v1::TrainParams ToProto(const ModelTrainParams& m) {
  v1::TrainParams p;
  p.set_num_states(static_cast<std::uint32_t>(m.num_states));
  p.set_window(static_cast<std::uint32_t>(m.window));
  p.set_num_clusters(static_cast<std::uint32_t>(m.num_clusters));
  p.set_covariance(m.full_covariance ? v1::COVARIANCE_TYPE_FULL : v1::COVARIANCE_TYPE_DIAGONAL);
  p.set_hmm_restarts(static_cast<std::uint32_t>(m.hmm_restarts));
  p.set_hmm_max_iterations(static_cast<std::uint32_t>(m.hmm_max_iterations));
  p.set_hmm_tolerance(m.hmm_tolerance);
  p.set_crf_l2(m.crf_l2);
  p.set_crf_max_iterations(static_cast<std::uint32_t>(m.crf_max_iterations));
  p.set_crf_tolerance(m.crf_tolerance);
  p.set_seed(m.seed);
  p.set_variance_floor(m.variance_floor);
  return p;
}

v1::ModelInfo MakeModelInfo(const RemappedModel& model, const ModelTrainParams& params,
                            const TrainReport& report, std::uint32_t training_sequences,
                            std::string_view description) {
  v1::ModelInfo info;
  info.set_num_states(static_cast<std::uint32_t>(model.num_states()));
  info.set_window(static_cast<std::uint32_t>(model.window()));
  info.set_lookahead_steps(static_cast<std::uint32_t>(model.lookahead()));
  info.set_num_clusters(static_cast<std::uint32_t>(model.num_clusters()));
  info.set_covariance(model.hmm().full_covariance() ? v1::COVARIANCE_TYPE_FULL
                                                    : v1::COVARIANCE_TYPE_DIAGONAL);
  info.set_training_data_s(report.data_s);
  info.set_training_sequences(training_sequences);
  info.set_training_steps(report.steps);
  info.set_train_s(report.train_s);
  info.set_train_crf_ll_per_step(report.crf_ll_per_step);
  info.set_train_hmm_ll_per_step(report.hmm_ll_per_step);
  *info.mutable_params() = ToProto(params);
  info.set_description(std::string(description));
  info.set_format_version(kModelFormatVersion);
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now).count();
  info.mutable_created_time()->set_seconds(ns / 1000000000);
  info.mutable_created_time()->set_nanos(static_cast<int>(ns % 1000000000));
  return info;
}

v1::Sequence ToProto(const PairedSequence& s) {
  v1::Sequence out;
  out.set_name(s.name);
  for (const auto& x : s.inputs) {
    auto* f = out.add_inputs();
    f->set_start_s(x.start_s);
    f->set_end_s(x.end_s);
    f->set_f0_mean_hz(x.f0_mean_hz);
    f->set_intensity_mean_db(x.intensity_mean_db);
    f->set_length_s(x.length_s);
    f->set_voiced(x.voiced);
  }
  for (Eigen::Index t = 0; t < s.outputs.rows(); ++t) {
    auto* y = out.add_outputs();
    y->set_temporal_extent(s.outputs(t, 0));
    y->set_spatial_extent(s.outputs(t, 1));
    y->set_velocity(s.outputs(t, 2));
    y->set_acceleration(s.outputs(t, 3));
    y->set_curvature(s.outputs(t, 4));
    y->set_hand_height(s.outputs(t, 5));
  }
  return out;
}

v1::ModelParameters MakeModelParameters(const RemappedModel& model) {
  v1::ModelParameters p;
  const int s = model.num_states();
  p.set_num_states(static_cast<std::uint32_t>(s));
  // The initial distribution of the CRF chain without inputs: softmax(b).
  Eigen::VectorXd init = model.crf().exp_initial();
  init /= init.sum();
  FromVector(init, p.mutable_initial_probabilities());
  const Eigen::MatrixXd t = model.crf().NormalizedTransition();
  for (int i = 0; i < s; ++i)
    for (int j = 0; j < s; ++j) p.add_transition_probabilities(t(i, j));
  for (int i = 0; i < s; ++i) {
    auto* g = p.add_states();
    for (int d = 0; d < kKinematicDims; ++d) g->add_mean(model.hmm().means()(i, d));
    const auto& c = model.hmm().covariances()[i];
    if (model.hmm().full_covariance()) {
      for (int r = 0; r < kKinematicDims; ++r)
        for (int col = 0; col < kKinematicDims; ++col) g->add_covariance(c(r, col));
    } else {
      for (int d = 0; d < kKinematicDims; ++d) g->add_covariance(c(d, d));
    }
  }
  return p;
}

std::string ModelSummaryJson(const v1::ModelInfo& info) {
  const nlohmann::json j{
      {"num_states", info.num_states()},
      {"window", info.window()},
      {"lookahead_steps", info.lookahead_steps()},
      {"num_clusters", info.num_clusters()},
      {"covariance", info.covariance() == v1::COVARIANCE_TYPE_FULL ? "full" : "diagonal"},
      {"training_data_s", info.training_data_s()},
      {"training_sequences", info.training_sequences()},
      {"training_steps", info.training_steps()},
      {"train_s", info.train_s()},
      {"train_crf_ll_per_step", info.train_crf_ll_per_step()},
      {"train_hmm_ll_per_step", info.train_hmm_ll_per_step()}};
  return j.dump();
}

namespace {

// Serialises a model file into a draft as model.kmodel.
Status WriteToDraft(store::Draft& draft, const v1::ModelFile& file) {
  std::string bytes;
  if (!file.SerializeToString(&bytes)) return absl::InternalError("model: serialisation failed");
  return draft.WriteFile(kModelFileName, bytes);
}

store::ArtifactMeta MetaFor(const v1::ModelInfo& info, std::vector<store::ArtifactRef> depends_on) {
  store::ArtifactMeta meta;
  meta.description = info.description();
  meta.summary_json = ModelSummaryJson(info);
  meta.depends_on = std::move(depends_on);
  return meta;
}

}  // namespace

StatusOr<std::unique_ptr<ModelStore>> ModelStore::Open(const std::string& root, std::string_view field) {
  if (root.empty()) return InvalidField(field, "is required");
  KINEMO_ASSIGN_OR_RETURN(auto artifacts, store::ArtifactStore::Open(root, field));
  std::unique_ptr<ModelStore> out(new ModelStore(std::move(artifacts)));
  KINEMO_RETURN_IF_ERROR(out->ImportLegacy());
  return out;
}

Status ModelStore::ImportLegacy() {
  std::error_code ec;
  std::vector<std::string> ids;
  for (auto it = fs::directory_iterator(store_->root(), ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (it->is_directory() && store::IsValidId(name)) ids.push_back(name);
  }
  std::sort(ids.begin(), ids.end());
  for (const std::string& id : ids) {
    std::vector<std::uint32_t> versions;
    for (auto it = fs::directory_iterator(fs::path(store_->root()) / id, ec); !ec && it != fs::directory_iterator();
         it.increment(ec)) {
      std::uint32_t v = 0;
      if (it->is_regular_file() && ParseVersionFile(it->path().filename().string(), &v)) versions.push_back(v);
    }
    ec.clear();
    if (versions.empty() || store_->Get(store::kModels, id).ok()) continue;
    std::sort(versions.begin(), versions.end());
    for (std::uint32_t v : versions) {
      const std::string path = (fs::path(store_->root()) / id / kinemo::StrCat("v", v, ".kmodel")).string();
      KINEMO_ASSIGN_OR_RETURN(v1::ModelFile file, ReadModelFile(path));
      if (auto decoded = DecodeModel(file); !decoded.ok()) return Annotate(decoded.status(), path);
      file.mutable_info()->set_model_id(id);
      KINEMO_ASSIGN_OR_RETURN(store::Draft draft, store_->Begin(store::kModels, id));
      KINEMO_RETURN_IF_ERROR(WriteToDraft(draft, file));
      KINEMO_RETURN_IF_ERROR(store_->Commit(std::move(draft), MetaFor(file.info(), {}), true).status());
    }
  }
  return absl::OkStatus();
}

StatusOr<std::vector<store::ArtifactMeta>> ModelStore::ImportSeed(const std::string& seed_root) {
  return store_->ImportSeed(seed_root, store::kModels);
}

StatusOr<v1::ModelInfo> ModelStore::Save(const RemappedModel& model, v1::ModelInfo info, bool overwrite) {
  KINEMO_RETURN_IF_ERROR(ValidateModelId(info.model_id()));
  KINEMO_ASSIGN_OR_RETURN(store::Draft draft, store_->Begin(store::kModels, info.model_id()));
  // The version written into the file is informative; the folder decides.
  info.set_version(0);
  const v1::ModelFile file = EncodeModel(model, info);
  KINEMO_RETURN_IF_ERROR(WriteToDraft(draft, file));
  KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta,
                          store_->Commit(std::move(draft), MetaFor(file.info(), {}), overwrite));
  KINEMO_ASSIGN_OR_RETURN(LoadedModel loaded, LoadVersion(meta));
  return loaded.info;
}

StatusOr<LoadedModel> ModelStore::CommitPushed(store::Draft draft, std::string_view file_field, bool overwrite,
                                               std::string_view description,
                                               std::vector<store::ArtifactRef> depends_on) {
  KINEMO_ASSIGN_OR_RETURN(std::string path, draft.PathFor(kModelFileName));
  std::ifstream in(path, std::ios::binary);
  if (!in) return InvalidField(file_field, "'", kModelFileName, "' is missing");
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  v1::ModelFile file;
  if (!file.ParseFromString(bytes)) {
    return InvalidField(file_field, "'", kModelFileName, "' is not a kinemo model file (", bytes.size(),
                        " bytes that do not parse as kinemo.inference.v1.ModelFile)");
  }
  auto model = DecodeModel(file);
  if (!model.ok()) {
    return InvalidField(file_field, "'", kModelFileName, "' is not a valid model: ", model.status().message());
  }
  file.mutable_info()->set_model_id(draft.id());
  file.mutable_info()->set_version(0);
  if (!description.empty()) file.mutable_info()->set_description(std::string(description));
  KINEMO_RETURN_IF_ERROR(WriteToDraft(draft, file));
  KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta,
                          store_->Commit(std::move(draft), MetaFor(file.info(), std::move(depends_on)), overwrite));
  LoadedModel loaded{file.info(), std::make_shared<const RemappedModel>(*std::move(model))};
  loaded.info.set_model_id(meta.id);
  loaded.info.set_version(meta.version);
  std::lock_guard<std::mutex> lock(mu_);
  cache_[{meta.id, meta.version}] = loaded;
  return loaded;
}

StatusOr<LoadedModel> ModelStore::LoadVersion(const store::ArtifactMeta& meta) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = cache_.find({meta.id, meta.version}); it != cache_.end()) return it->second;
  }
  const std::string path = store_->FilePath(meta.ref(), kModelFileName);
  KINEMO_ASSIGN_OR_RETURN(v1::ModelFile file, ReadModelFile(path));
  auto model_or = DecodeModel(file);
  if (!model_or.ok()) return Annotate(model_or.status(), path);
  LoadedModel loaded{file.info(), std::make_shared<const RemappedModel>(*std::move(model_or))};
  // The id and version a model is called by are its folders'.
  loaded.info.set_model_id(meta.id);
  loaded.info.set_version(meta.version);
  std::lock_guard<std::mutex> lock(mu_);
  return cache_.emplace(std::make_pair(meta.id, meta.version), std::move(loaded)).first->second;
}

StatusOr<LoadedModel> ModelStore::Load(std::string_view id, std::uint32_t version) {
  KINEMO_RETURN_IF_ERROR(ValidateModelId(id));
  if (version != 0) {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = cache_.find({std::string(id), version}); it != cache_.end()) return it->second;
  }
  auto meta = store_->Get(store::kModels, id, version);
  if (!meta.ok()) {
    if (version == 0) return absl::NotFoundError(kinemo::StrCat("model_id: no model '", id, "'"));
    return absl::NotFoundError(kinemo::StrCat("version: no version ", version, " of model '", id, "'"));
  }
  return LoadVersion(*meta);
}

StatusOr<std::vector<v1::ModelInfo>> ModelStore::List(bool all_versions) {
  KINEMO_ASSIGN_OR_RETURN(auto metas, store_->List(store::kModels, "", all_versions));
  std::vector<v1::ModelInfo> out;
  for (const auto& meta : metas) {
    KINEMO_ASSIGN_OR_RETURN(LoadedModel m, LoadVersion(meta));
    out.push_back(m.info);
  }
  return out;
}

StatusOr<std::vector<store::ArtifactMeta>> ModelStore::ListArtifacts(std::string_view id, bool all_versions) const {
  return store_->List(store::kModels, id, all_versions);
}

StatusOr<std::vector<store::ArtifactMeta>> ModelStore::Delete(std::string_view id, std::uint32_t version) {
  KINEMO_ASSIGN_OR_RETURN(auto removed, store_->Delete(store::kModels, id, version));
  std::lock_guard<std::mutex> lock(mu_);
  for (const auto& m : removed) cache_.erase({m.id, m.version});
  return removed;
}

}  // namespace kinemo::inference
