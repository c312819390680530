#include "services/inference/inference_service.h"

#include <chrono>
#include <deque>
#include <filesystem>
#include <mutex>
#include <thread>

#include "common/grpc/request_check.h"
#include "common/grpc/status_mapping.h"
#include "common/grpc/worker_write_reactor.h"
#include "common/logging/log.h"
#include "services/inference/corpus/corpus.h"

namespace kinemo::inference {
namespace {

namespace fs = std::filesystem;

grpc::ServerUnaryReactor* Done(grpc::CallbackServerContext* ctx, const Status& status) {
  auto* r = ctx->DefaultReactor();
  r->Finish(ToGrpcStatus(status));
  return r;
}

void FillBelief(std::uint64_t step, const ProsodyStep& x, const double* p, int s, v1::Belief* b) {
  b->set_step(step);
  b->set_start_s(x.start_s);
  b->set_end_s(x.end_s);
  b->mutable_probabilities()->Reserve(s);
  for (int i = 0; i < s; ++i) b->add_probabilities(p[i]);
}

std::uint64_t MaxSequenceSteps(const v1::InferenceOptions& o) {
  return o.max_sequence_steps() != 0 ? o.max_sequence_steps() : 1000000;
}
std::uint64_t MaxTrainingSteps(const v1::InferenceOptions& o) {
  return o.max_training_steps() != 0 ? o.max_training_steps() : 10000000;
}

StatusOr<std::vector<PairedSequence>> LoadData(InferenceServiceImpl& svc, const v1::TrainingSet* inline_set,
                                               const std::string* corpus_dir, std::uint64_t max_steps) {
  std::vector<PairedSequence> data;
  if (inline_set != nullptr) {
    for (int k = 0; k < inline_set->sequences_size(); ++k) {
      KINEMO_ASSIGN_OR_RETURN(PairedSequence s,
                              FromProto(inline_set->sequences(k), kinemo::StrCat("sequences[", k, "]")));
      data.push_back(std::move(s));
    }
  } else if (corpus_dir != nullptr) {
    KINEMO_ASSIGN_OR_RETURN(std::string dir, svc.ResolveCorpus(*corpus_dir));
    KINEMO_ASSIGN_OR_RETURN(data, ImportPairedCorpus(dir));
  }
  if (data.empty()) return InvalidField("sequences", "no data (give sequences or corpus_dir)");
  std::uint64_t steps = 0;
  for (const auto& s : data) steps += s.inputs.size();
  if (steps > max_steps) return InvalidField("sequences", steps, " steps exceed the limit of ", max_steps);
  return data;
}

// ---------------------------------------------------------------------------
// Train: a worker thread trains; progress messages are queued and written
// one at a time.
class TrainReactor final : public WorkerWriteReactor<v1::TrainResponse> {
 public:
  TrainReactor(InferenceServiceImpl* svc, const v1::TrainRequest* request) : svc_(svc), request_(*request) {
    const std::uint32_t limit = svc_->options().max_concurrent_trainings() != 0
                                    ? svc_->options().max_concurrent_trainings() : 1;
    if (!TakeSlot(&svc_->trainings, static_cast<int>(limit), "max_concurrent_trainings", "trainings")) return;
    StartWorker([this] { return Run(); });
  }

 private:
  Status Run() {
    const auto start = std::chrono::steady_clock::now();
    KINEMO_RETURN_IF_ERROR(ValidateModelId(request_.model_id()));
    // Values as sent, names as the request's ("params.num_states: ...").
    KINEMO_RETURN_IF_ERROR(CheckFitsInt(request_.params(), "params"));
    const ModelTrainParams params = FromProto(request_.params(), svc_->options().defaults());
    KINEMO_RETURN_IF_ERROR(UnderField(ValidateTrainParams(params), "params"));
    Send("import", 0, 0.0, "");
    KINEMO_ASSIGN_OR_RETURN(
        std::vector<PairedSequence> data,
        LoadData(*svc_, request_.has_sequences() ? &request_.sequences() : nullptr,
                 request_.has_corpus_dir() ? &request_.corpus_dir() : nullptr,
                 MaxTrainingSteps(svc_->options())));
    static const char* kStages[] = {"import", "hmm_em", "clustering", "crf_optimize", "baseline", "saving"};
    auto last = std::chrono::steady_clock::now() - std::chrono::seconds(1);
    std::string last_stage;
    TrainReport report;
    ModelTrainParams p = params;
    p.threads = svc_->options().training_threads() != 0
                    ? static_cast<int>(svc_->options().training_threads())
                    : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    auto model = RemappedModel::Train(
        data, p,
        [&](std::string_view stage, double fraction, std::string_view message) {
          if (cancelled()) return false;
          const auto now = std::chrono::steady_clock::now();
          if (stage != last_stage || now - last > std::chrono::milliseconds(200)) {
            last = now;
            last_stage = std::string(stage);
            int index = 0;
            for (int k = 0; k < 6; ++k)
              if (stage == kStages[k]) index = k;
            Send(stage, index, fraction, message,
                 std::chrono::duration<double>(now - start).count());
          }
          return !cancelled();
        },
        &report);
    if (cancelled()) return absl::CancelledError("training cancelled; nothing was saved");
    if (!model.ok()) return model.status();
    Send("saving", 5, 0.0, "");
    v1::ModelInfo info = MakeModelInfo(*model, params, report, static_cast<std::uint32_t>(data.size()),
                                       request_.description());
    info.set_model_id(request_.model_id());
    KINEMO_ASSIGN_OR_RETURN(v1::ModelInfo saved, svc_->store().Save(*model, info, request_.overwrite()));
    v1::TrainResponse last_msg;
    auto* pr = last_msg.mutable_progress();
    pr->set_stage("saving");
    pr->set_stage_index(5);
    pr->set_stage_count(6);
    pr->set_stage_fraction(1.0);
    pr->set_fraction(1.0);
    pr->set_elapsed_s(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    *last_msg.mutable_model() = saved;
    Enqueue(std::move(last_msg));
    log::Info("model_trained", {{"model_id", saved.model_id()},
                                {"version", static_cast<int>(saved.version())},
                                {"train_s", saved.train_s()},
                                {"request_id", request_.request_id()}});
    return absl::OkStatus();
  }

  void Send(std::string_view stage, int index, double fraction, std::string_view message,
            double elapsed_s = 0.0) {
    v1::TrainResponse r;
    auto* p = r.mutable_progress();
    p->set_stage(std::string(stage));
    p->set_stage_index(static_cast<std::uint32_t>(index));
    p->set_stage_count(6);
    p->set_stage_fraction(fraction);
    p->set_fraction((index + fraction) / 6.0);
    p->set_elapsed_s(elapsed_s);
    p->set_message(std::string(message));
    Enqueue(std::move(r));
  }

  InferenceServiceImpl* svc_;
  const v1::TrainRequest request_;
};

// ---------------------------------------------------------------------------
// StreamInfer: config, then features → α.
class StreamReactor final
    : public grpc::ServerBidiReactor<v1::StreamInferRequest, v1::StreamInferResponse> {
 public:
  explicit StreamReactor(InferenceServiceImpl* svc) : svc_(svc) {
    const std::uint32_t limit = svc_->options().max_concurrent_streams() != 0
                                    ? svc_->options().max_concurrent_streams() : 1024;
    if (svc_->streams.fetch_add(1) >= static_cast<int>(limit)) {
      std::lock_guard<std::mutex> lock(mu_);
      FailLocked(absl::ResourceExhaustedError(
          kinemo::StrCat("max_concurrent_streams: ", limit, " streams are open")));
      return;
    }
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (finished_) return;
    if (!ok) {  // half-close: answer the steps still waiting
      if (filter_) {
        while (filter_->Finish(alpha_)) EmitLocked();
      }
      reads_done_ = true;
      MaybeFinishLocked();
      return;
    }
    if (!filter_) {
      if (!request_.has_config()) {
        FailLocked(InvalidField("config", "the first message must be a StreamInferConfig"));
        return;
      }
      auto loaded = svc_->store().Load(request_.config().model_id(), request_.config().version());
      if (!loaded.ok()) {
        FailLocked(loaded.status());
        return;
      }
      loaded_ = *std::move(loaded);
      filter_ = std::make_unique<OnlineFilter>(*loaded_.model);
      alpha_.assign(static_cast<size_t>(loaded_.model->num_states()), 0.0);
      v1::StreamInferResponse r;
      *r.mutable_model() = loaded_.info;
      EnqueueLocked(std::move(r));
    } else {
      if (!request_.has_features()) {
        FailLocked(InvalidField("features", "expected features after the config (config given twice?)"));
        return;
      }
      const ProsodyStep x = FromProto(request_.features());
      if (Status st = ValidateProsodyStep(x, kinemo::StrCat("features[", received_, "]")); !st.ok()) {
        FailLocked(st);
        return;
      }
      ++received_;
      pending_.push_back(x);
      if (filter_->Push(x, alpha_)) EmitLocked();
    }
    StartRead(&request_);
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mu_);
    queue_.pop_front();
    if (!ok) queue_.clear();
    if (!queue_.empty()) {
      StartWrite(&queue_.front());
    } else {
      writing_ = false;
      MaybeFinishLocked();
    }
  }

  void OnDone() override {
    svc_->streams.fetch_sub(1);
    delete this;
  }

 private:
  void EmitLocked() {
    v1::StreamInferResponse r;
    const std::uint64_t step = static_cast<std::uint64_t>(filter_->next_step() - 1);
    FillBelief(step, pending_.front(), alpha_.data(), static_cast<int>(alpha_.size()), r.mutable_filtered());
    pending_.pop_front();
    EnqueueLocked(std::move(r));
  }
  void EnqueueLocked(v1::StreamInferResponse r) {
    queue_.push_back(std::move(r));
    if (!writing_) {
      writing_ = true;
      StartWrite(&queue_.front());
    }
  }
  void FailLocked(const Status& st) {
    final_ = st;
    reads_done_ = true;
    MaybeFinishLocked();
  }
  void MaybeFinishLocked() {
    if (reads_done_ && !writing_ && !finished_) {
      finished_ = true;
      Finish(ToGrpcStatus(final_));
    }
  }

  InferenceServiceImpl* svc_;
  std::mutex mu_;
  v1::StreamInferRequest request_;
  LoadedModel loaded_;
  std::unique_ptr<OnlineFilter> filter_;
  std::vector<double> alpha_;
  std::deque<ProsodyStep> pending_;  // inputs whose belief is not yet sent
  std::deque<v1::StreamInferResponse> queue_;
  std::uint64_t received_ = 0;
  bool writing_ = false, reads_done_ = false, finished_ = false;
  Status final_;
};

}  // namespace

ProsodyStep FromProto(const v1::ProsodyFeatures& f) {
  ProsodyStep s;
  s.start_s = f.start_s();
  s.end_s = f.end_s();
  s.f0_mean_hz = f.f0_mean_hz();
  s.intensity_mean_db = f.intensity_mean_db();
  s.length_s = f.length_s();
  s.voiced = f.voiced();
  return s;
}

StatusOr<PairedSequence> FromProto(const v1::Sequence& s, std::string_view field) {
  PairedSequence out;
  out.name = s.name();
  for (const auto& x : s.inputs()) out.inputs.push_back(FromProto(x));
  if (s.outputs_size() != s.inputs_size())
    return InvalidField(kinemo::StrCat(field, ".outputs"), "has ", s.outputs_size(),
                        " steps but inputs have ", s.inputs_size());
  out.outputs.resize(s.outputs_size(), kKinematicDims);
  for (int t = 0; t < s.outputs_size(); ++t) {
    const auto& y = s.outputs(t);
    out.outputs.row(t) << y.temporal_extent(), y.spatial_extent(), y.velocity(), y.acceleration(),
        y.curvature(), y.hand_height();
  }
  KINEMO_RETURN_IF_ERROR(ValidatePairedSequence(out, field));
  return out;
}

StatusOr<std::shared_ptr<InferenceServiceImpl>> InferenceServiceImpl::Create(
    const v1::InferenceOptions& options) {
  std::shared_ptr<InferenceServiceImpl> svc(new InferenceServiceImpl(options));
  const bool old_name = options.store_dir().empty() && !options.model_dir().empty();
  const std::string& dir = old_name ? options.model_dir() : options.store_dir();
  if (dir.empty()) return InvalidField("store_dir", "is required (the folder of the service's artifact store)");
  KINEMO_ASSIGN_OR_RETURN(svc->store_, ModelStore::Open(dir, old_name ? "model_dir" : "store_dir"));
  auto seeded = svc->store_->ImportSeed(options.seed_store_dir());
  if (!seeded.ok()) return Annotate(seeded.status(), "seed_store_dir");
  for (const auto& m : *seeded) {
    log::Info("model_seeded", {{"model_id", m.id}, {"version", static_cast<int>(m.version)}});
  }
  // Every model is loaded at start (the newest version of each id).
  KINEMO_ASSIGN_OR_RETURN(auto stored, svc->store_->ListArtifacts("", false));
  for (const auto& m : stored) {
    auto loaded = svc->store_->Load(m.id, m.version);
    if (!loaded.ok()) {
      log::Warn("model_unreadable", {{"model_id", m.id},
                                     {"version", static_cast<int>(m.version)},
                                     {"error", std::string(loaded.status().message())}});
    }
  }
  for (const auto& id : options.preload_model_ids()) {
    auto m = svc->store_->Load(id, 0);
    if (!m.ok()) return Annotate(m.status(), "preload_model_ids");
  }
  auto push = std::make_shared<ArtifactPushHandler>();
  push->store = &svc->store_->artifacts();  // drafts are staged in the store they commit to
  push->kinds = {std::string(store::kModels)};
  push->max_bytes = options.max_artifact_bytes() != 0 ? options.max_artifact_bytes() : kDefaultMaxArtifactBytes;
  push->check_header = [](const common::v1::PushArtifactHeader& h) -> Status {
    if (h.files_size() != 1 || h.files(0).name() != kModelFileName) {
      return InvalidField("header.files", "a model is one file named '", kModelFileName, "'");
    }
    return absl::OkStatus();
  };
  ModelStore* models = svc->store_.get();
  push->commit = [models](store::Draft draft, const common::v1::PushArtifactHeader& h)
      -> StatusOr<common::v1::PushArtifactResponse> {
    std::vector<store::ArtifactRef> deps;
    for (const auto& d : h.depends_on()) deps.push_back(kinemo::FromProto(d));
    KINEMO_ASSIGN_OR_RETURN(LoadedModel loaded, models->CommitPushed(std::move(draft), "header.files[0]", h.overwrite(),
                                                                     h.description(), std::move(deps)));
    KINEMO_ASSIGN_OR_RETURN(store::ArtifactMeta meta,
                            models->artifacts().Get(store::kModels, loaded.info.model_id(), loaded.info.version()));
    log::Info("model_pushed", {{"model_id", meta.id}, {"version", static_cast<int>(meta.version)},
                               {"request_id", h.request_id()}});
    common::v1::PushArtifactResponse response;
    *response.mutable_artifact() = kinemo::ToProto(meta);
    return response;
  };
  svc->push_ = std::move(push);
  return svc;
}

StatusOr<std::string> InferenceServiceImpl::ResolveCorpus(const std::string& relative) const {
  if (options_.corpus_root().empty())
    return absl::FailedPreconditionError("corpus_dir: server-side corpora are disabled (no corpus_root)");
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(options_.corpus_root(), ec);
  const fs::path p = fs::weakly_canonical(fs::path(options_.corpus_root()) / relative, ec);
  const std::string rs = root.string(), ps = p.string();
  if (fs::path(relative).is_absolute() || ps.compare(0, rs.size(), rs) != 0)
    return absl::FailedPreconditionError(kinemo::StrCat("corpus_dir: '", relative, "' is outside corpus_root"));
  return ps;
}

grpc::ServerWriteReactor<v1::TrainResponse>* InferenceServiceImpl::Train(
    grpc::CallbackServerContext*, const v1::TrainRequest* request) {
  return new TrainReactor(this, request);
}

grpc::ServerUnaryReactor* InferenceServiceImpl::Infer(grpc::CallbackServerContext* ctx,
                                                      const v1::InferRequest* request,
                                                      v1::InferResponse* response) {
  if (static_cast<std::uint64_t>(request->inputs_size()) > MaxSequenceSteps(options_))
    return Done(ctx, InvalidField("inputs", request->inputs_size(), " steps exceed the limit"));
  auto loaded = store_->Load(request->model_id(), request->version());
  if (!loaded.ok()) return Done(ctx, loaded.status());
  std::vector<ProsodyStep> xs;
  xs.reserve(static_cast<size_t>(request->inputs_size()));
  for (const auto& f : request->inputs()) xs.push_back(FromProto(f));
  auto r = loaded->model->Infer(xs, request->include_filtered(), request->include_viterbi());
  if (!r.ok()) return Done(ctx, r.status());
  const int s = loaded->model->num_states();
  *response->mutable_model() = loaded->info;
  for (size_t t = 0; t < xs.size(); ++t) {
    FillBelief(t, xs[t], r->smoothed.row(static_cast<Eigen::Index>(t)).data(), s, response->add_smoothed());
    if (request->include_filtered())
      FillBelief(t, xs[t], r->filtered.row(static_cast<Eigen::Index>(t)).data(), s, response->add_filtered());
  }
  for (int q : r->viterbi) response->add_viterbi_states(static_cast<std::uint32_t>(q));
  if (request->include_expected_kinematics()) {
    const Eigen::MatrixXd e = r->smoothed * loaded->model->hmm().means();
    for (Eigen::Index t = 0; t < e.rows(); ++t) {
      auto* k = response->add_expected_kinematics();
      k->set_temporal_extent(e(t, 0));
      k->set_spatial_extent(e(t, 1));
      k->set_velocity(e(t, 2));
      k->set_acceleration(e(t, 3));
      k->set_curvature(e(t, 4));
      k->set_hand_height(e(t, 5));
    }
  }
  response->set_request_id(request->request_id());
  return Done(ctx, absl::OkStatus());
}

grpc::ServerBidiReactor<v1::StreamInferRequest, v1::StreamInferResponse>*
InferenceServiceImpl::StreamInfer(grpc::CallbackServerContext*) {
  return new StreamReactor(this);
}

grpc::ServerUnaryReactor* InferenceServiceImpl::Evaluate(grpc::CallbackServerContext* ctx,
                                                         const v1::EvaluateRequest* request,
                                                         v1::EvaluateResponse* response) {
  auto loaded = store_->Load(request->model_id(), request->version());
  if (!loaded.ok()) return Done(ctx, loaded.status());
  auto data = LoadData(*this, request->has_sequences() ? &request->sequences() : nullptr,
                       request->has_corpus_dir() ? &request->corpus_dir() : nullptr,
                       MaxTrainingSteps(options_));
  if (!data.ok()) return Done(ctx, data.status());
  double crf = 0, hmm = 0;
  std::uint64_t steps = 0;
  for (const auto& seq : *data) {
    auto sc = loaded->model->Evaluate(seq);
    if (!sc.ok()) return Done(ctx, sc.status());
    auto* out = response->add_sequences();
    out->set_name(seq.name);
    out->set_steps(sc->steps);
    out->set_crf_ll_per_step(sc->crf_ll_per_step);
    out->set_hmm_ll_per_step(sc->hmm_ll_per_step);
    crf += sc->crf_ll_per_step * static_cast<double>(sc->steps);
    hmm += sc->hmm_ll_per_step * static_cast<double>(sc->steps);
    steps += sc->steps;
  }
  *response->mutable_model() = loaded->info;
  response->set_crf_ll_per_step(crf / static_cast<double>(steps));
  response->set_hmm_ll_per_step(hmm / static_cast<double>(steps));
  response->set_steps(steps);
  response->set_request_id(request->request_id());
  return Done(ctx, absl::OkStatus());
}

grpc::ServerUnaryReactor* InferenceServiceImpl::GetModel(grpc::CallbackServerContext* ctx,
                                                         const v1::GetModelRequest* request,
                                                         v1::GetModelResponse* response) {
  auto loaded = store_->Load(request->model_id(), request->version());
  if (!loaded.ok()) return Done(ctx, loaded.status());
  *response->mutable_info() = loaded->info;
  if (request->include_parameters()) *response->mutable_parameters() = MakeModelParameters(*loaded->model);
  return Done(ctx, absl::OkStatus());
}

grpc::ServerUnaryReactor* InferenceServiceImpl::ListModels(grpc::CallbackServerContext* ctx,
                                                           const v1::ListModelsRequest* request,
                                                           v1::ListModelsResponse* response) {
  auto list = store_->List(request->all_versions());
  if (!list.ok()) return Done(ctx, list.status());
  for (auto& m : *list) *response->add_models() = std::move(m);
  return Done(ctx, absl::OkStatus());
}

grpc::ServerReadReactor<common::v1::PushArtifactRequest>* InferenceServiceImpl::PushArtifact(
    grpc::CallbackServerContext* ctx, common::v1::PushArtifactResponse* response) {
  return NewArtifactPushReactor(ctx, response, push_);
}

grpc::ServerUnaryReactor* InferenceServiceImpl::ListArtifacts(grpc::CallbackServerContext* ctx,
                                                              const common::v1::ListArtifactsRequest* request,
                                                              common::v1::ListArtifactsResponse* response) {
  if (Status s = ValidateListRequest(*request, push_->kinds); !s.ok()) return Done(ctx, s);
  auto list = store_->ListArtifacts(request->id(), request->all_versions());
  if (!list.ok()) return Done(ctx, list.status());
  AddInfos(*list, response->mutable_artifacts());
  return Done(ctx, absl::OkStatus());
}

grpc::ServerUnaryReactor* InferenceServiceImpl::DeleteArtifact(grpc::CallbackServerContext* ctx,
                                                               const common::v1::DeleteArtifactRequest* request,
                                                               common::v1::DeleteArtifactResponse* response) {
  if (Status s = ValidateDeleteRequest(*request, push_->kinds); !s.ok()) return Done(ctx, s);
  auto removed = store_->Delete(request->ref().id(), request->ref().version());
  if (!removed.ok()) return Done(ctx, InRef(removed.status()));
  for (const auto& m : *removed) {
    log::Info("model_deleted", {{"model_id", m.id}, {"version", static_cast<int>(m.version)}});
  }
  AddInfos(*removed, response->mutable_deleted());
  return Done(ctx, absl::OkStatus());
}

}  // namespace kinemo::inference
