#include "services/prosody/prosody_service.h"

#include "absl/strings/str_replace.h"

#include <chrono>
#include <cmath>
#include <deque>
#include <mutex>
#include <string>

#include "common/audio/decode.h"
#include "common/server/capacity.h"
#include "common/audio/resample.h"
#include "common/grpc/cancel_token.h"
#include "common/grpc/request_check.h"
#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "common/store/artifact_store.h"
#include "services/prosody/core/face_model.h"
#include "services/prosody/core/pipeline.h"
#include "services/prosody/core/streaming.h"
#ifdef KINEMO_WITH_SPHINX
#include "services/prosody/core/recognizer.h"
#endif

namespace kinemo::prosody {
namespace {

constexpr int kMinRateHz = 8000;
// A live phone is sent once the recognizer's best path has kept it this long
// after its end (bench/tools/phone_eval.cc scores the live phones).
constexpr double kLivePhoneLagS = 0.3;
constexpr int kMaxRateHz = 96000;

double Or(double v, double d) { return v > 0 ? v : d; }

void FillSyllable(const Syllable& s, v1::Syllable* out) {
  out->set_start_s(s.start_s);
  out->set_end_s(s.end_s);
  out->set_f0_mean_hz(s.f0_mean_hz);
  out->set_intensity_mean_db(s.intensity_mean_db);
  out->set_length_s(s.length_s);
  out->set_voiced(s.voiced);
  out->set_nucleus_time_s(s.nucleus_time_s);
  out->set_accent_index(s.accent_index);
}

void FillAccent(const Accent& a, common::v1::PitchAccent* out) {
  out->set_time_s(a.time_s);
  out->set_strength(a.strength);
  out->set_psi(a.psi);
  out->set_syllable_index(a.syllable_index);
  out->set_syllable_start_s(a.syllable_start_s);
  out->set_syllable_end_s(a.syllable_end_s);
  out->set_before_pause(a.before_pause);
}

void FillParams(const AnalysisOptions& o, v1::AnalysisParams* p) {
  p->set_pitch_floor_hz(o.pitch.floor_hz);
  p->set_pitch_ceiling_hz(o.pitch.ceiling_hz);
  p->set_voicing_threshold(o.pitch.voicing_threshold);
  p->set_silence_threshold_db(o.segmentation.silence_threshold_db);
  p->set_min_dip_db(o.segmentation.min_dip_db);
  p->set_min_pause_s(o.segmentation.min_pause_s);
  p->set_accent_threshold(o.accent.threshold);
  p->set_min_accent_distance_s(o.accent.min_distance_s);
  p->set_pre_pause_bonus(o.accent.pre_pause_bonus);
  p->set_viterbi_lag_s(o.viterbi_lag_s);
}

Status CheckFormat(const common::v1::AudioFormat& f, const std::string& field, bool allow_file) {
  if (f.encoding() == common::v1::AUDIO_ENCODING_UNSPECIFIED) {
    return InvalidField(field + ".encoding", "not set");
  }
  if (f.encoding() == common::v1::AUDIO_ENCODING_FILE) {
    if (!allow_file) return InvalidField(field + ".encoding", "files are not accepted on streams; send PCM");
    return absl::OkStatus();
  }
  if (f.sample_rate_hz() < kMinRateHz || f.sample_rate_hz() > kMaxRateHz) {
    return InvalidField(field + ".sample_rate_hz", f.sample_rate_hz(), " is not supported (",
                        kMinRateHz, "..", kMaxRateHz, ")");
  }
  if (f.channels() > 2) {
    return InvalidField(field + ".channels", f.channels(), " is not supported (1 or 2)");
  }
  return absl::OkStatus();
}

audio::PcmEncoding ToPcm(common::v1::AudioEncoding e) {
  return e == common::v1::AUDIO_ENCODING_PCM_F32LE ? audio::PcmEncoding::kF32Le
                                                   : audio::PcmEncoding::kS16Le;
}

StatusOr<audio::DecodedAudio> DecodeRequestAudio(const common::v1::Audio& a, double max_s) {
  KINEMO_RETURN_IF_ERROR(CheckFormat(a.format(), "audio.format", true));
  audio::DecodeOptions options;
  options.limits.max_duration_s = max_s;
  options.limits.min_sample_rate_hz = kMinRateHz;
  options.limits.max_sample_rate_hz = kMaxRateHz;
  // Too long: the limit by its option's name, and where longer recordings go.
  auto too_long = [&](const Status& s) -> Status {
    if (s.message().find("limits.max_duration_s") == std::string_view::npos) return Annotate(s, "audio.data");
    return InvalidField("audio.data", "the recording is longer than max_audio_s (", max_s,
                        " s) of Analyze; analyse longer recordings with AnalyzeChunked");
  };
  if (a.format().encoding() == common::v1::AUDIO_ENCODING_FILE) {
    auto decoded = audio::DecodeAudio(std::string_view(a.data()), options);
    if (!decoded.ok()) return too_long(decoded.status());
    return decoded;
  }
  audio::RawPcmFormat format;
  format.encoding = ToPcm(a.format().encoding());
  format.sample_rate_hz = static_cast<int>(a.format().sample_rate_hz());
  format.channels = std::max(1, static_cast<int>(a.format().channels()));
  auto decoded = audio::DecodeRawPcm(std::string_view(a.data()), format, options);
  if (!decoded.ok()) return too_long(decoded.status());
  return decoded;
}

// The face models of `store_dir` (after importing the seed's): the newest
// version of each id. A version that cannot be read is logged and skipped.
std::map<std::string, std::shared_ptr<const FaceModel>, std::less<>> LoadFaceModels(const v1::ProsodyOptions& o) {
  std::map<std::string, std::shared_ptr<const FaceModel>, std::less<>> out;
  if (o.store_dir().empty()) return out;
  auto store = store::ArtifactStore::Open(o.store_dir(), "store_dir");
  if (!store.ok()) {
    log::Warn("face_models_unavailable", {{"error", std::string(store.status().message())}});
    return out;
  }
  if (!o.seed_store_dir().empty()) {
    if (auto seeded = (*store)->ImportSeed(o.seed_store_dir(), kFaceModelsKind); !seeded.ok()) {
      log::Warn("face_seed_failed", {{"error", std::string(seeded.status().message())}});
    }
  }
  auto metas = (*store)->List(kFaceModelsKind);
  if (!metas.ok()) return out;
  for (const store::ArtifactMeta& m : *metas) {
    const std::string path = (*store)->FilePath(m.ref(), kFaceModelFile);
    auto bytes = audio::ReadFileBytes(path, 64u << 20);
    StatusOr<FaceModel> model = bytes.ok() ? FaceModelFromJson(std::string_view(reinterpret_cast<const char*>(bytes->data()), bytes->size()),
                                                               store::RefString(m.ref()))
                                           : StatusOr<FaceModel>(bytes.status());
    if (!model.ok()) {
      log::Warn("face_model_skipped", {{"model", store::RefString(m.ref())}, {"error", std::string(model.status().message())}});
      continue;
    }
    out[m.id] = std::make_shared<const FaceModel>(*std::move(model));
    log::Info("face_model_loaded", {{"model", store::RefString(m.ref())}});
  }
  return out;
}

std::string RequestId(const std::string& given, std::atomic<uint64_t>& next) {
  return given.empty() ? kinemo::StrCat("prosody-", next.fetch_add(1)) : given;
}

}  // namespace

void FillFrame(const Frame& f, v1::Frame* out) {
  out->set_time_s(f.time_s);
  out->set_f0_hz(f.f0_hz);
  out->set_voiced(f.voiced);
  out->set_voicing_probability(f.voicing_probability);
  out->set_intensity_db(f.intensity_db);
}

Status CheckPcmFormat(const common::v1::AudioFormat& format, const std::string& field) {
  return CheckFormat(format, field, /*allow_file=*/false);
}

audio::PcmEncoding PcmEncodingOf(common::v1::AudioEncoding encoding) { return ToPcm(encoding); }

std::string ProsodyServiceImpl::NextRequestId(const std::string& given) {
  return RequestId(given, next_request_id_);
}

v1::ProsodyOptions WithDefaults(v1::ProsodyOptions o) {
  if (o.max_audio_s() <= 0) o.set_max_audio_s(600);
  if (o.max_chunked_audio_s() <= 0) o.set_max_chunked_audio_s(7200);
  if (o.max_concurrent_chunked() == 0) o.set_max_concurrent_chunked(2);
  if (o.max_stream_s() <= 0) o.set_max_stream_s(3600);
  if (o.max_chunk_s() <= 0) o.set_max_chunk_s(1);
  if (o.analysis_rate_hz() == 0) o.set_analysis_rate_hz(16000);
  if (o.max_concurrent_streams() == 0) o.set_max_concurrent_streams(static_cast<uint32_t>(server::DefaultLiveStreamLimit()));
  return o;
}

StatusOr<AnalysisOptions> ToAnalysisOptions(const v1::AnalysisParams& r, const v1::AnalysisParams& d,
                                            std::string_view field) {
  // Every AnalysisParams field is a double where 0 means "default".
  const auto* descriptor = v1::AnalysisParams::descriptor();
  const auto* reflection = v1::AnalysisParams::GetReflection();
  for (int i = 0; i < descriptor->field_count(); ++i) {
    const double v = reflection->GetDouble(r, descriptor->field(i));
    if (!std::isfinite(v) || v < 0) {
      return InvalidField(kinemo::StrCat(field, ".", descriptor->field(i)->name()), v,
                          " is not a finite number >= 0 (0 = the server's default)");
    }
  }
  AnalysisOptions o;
  o.pitch.floor_hz = Or(r.pitch_floor_hz(), Or(d.pitch_floor_hz(), o.pitch.floor_hz));
  o.pitch.ceiling_hz = Or(r.pitch_ceiling_hz(), Or(d.pitch_ceiling_hz(), o.pitch.ceiling_hz));
  o.pitch.voicing_threshold =
      Or(r.voicing_threshold(), Or(d.voicing_threshold(), o.pitch.voicing_threshold));
  o.segmentation.silence_threshold_db = Or(
      r.silence_threshold_db(), Or(d.silence_threshold_db(), o.segmentation.silence_threshold_db));
  o.segmentation.min_dip_db = Or(r.min_dip_db(), Or(d.min_dip_db(), o.segmentation.min_dip_db));
  o.segmentation.min_pause_s = Or(r.min_pause_s(), Or(d.min_pause_s(), o.segmentation.min_pause_s));
  o.accent.threshold = Or(r.accent_threshold(), Or(d.accent_threshold(), o.accent.threshold));
  o.accent.min_distance_s =
      Or(r.min_accent_distance_s(), Or(d.min_accent_distance_s(), o.accent.min_distance_s));
  o.accent.pre_pause_bonus =
      Or(r.pre_pause_bonus(), Or(d.pre_pause_bonus(), o.accent.pre_pause_bonus));
  o.viterbi_lag_s = Or(r.viterbi_lag_s(), Or(d.viterbi_lag_s(), o.viterbi_lag_s));
  return o;
}

Status ToRequestFields(const Status& status, std::string_view field) {
  if (status.ok()) return status;
  const std::string f(field);
  // Option path (core/options.h) -> AnalysisParams field, every one a request carries.
  const std::string message = absl::StrReplaceAll(
      status.message(), {{"pitch.floor_hz", f + ".pitch_floor_hz"},
                         {"pitch.ceiling_hz", f + ".pitch_ceiling_hz"},
                         {"pitch.voicing_threshold", f + ".voicing_threshold"},
                         {"segmentation.silence_threshold_db", f + ".silence_threshold_db"},
                         {"segmentation.min_dip_db", f + ".min_dip_db"},
                         {"segmentation.min_pause_s", f + ".min_pause_s"},
                         {"accent.threshold", f + ".accent_threshold"},
                         {"accent.min_distance_s", f + ".min_accent_distance_s"},
                         {"accent.pre_pause_bonus", f + ".pre_pause_bonus"},
                         {"viterbi_lag_s", f + ".viterbi_lag_s"}});
  return Status(status.code(), message);
}

ProsodyServiceImpl::ProsodyServiceImpl(const v1::ProsodyOptions& options)
    : options_(WithDefaults(options)),
      face_models_(LoadFaceModels(options_)),
      workers_(std::make_unique<server::WorkerPool>(options_.worker_threads(), /*max_queued=*/64)) {
#ifdef KINEMO_WITH_SPHINX
  if (!options_.recognizer().disabled()) {
    RecognizerConfig c;
    c.model_dir = options_.recognizer().model_dir();
    c.dictionary_file = options_.recognizer().dictionary_file();
    c.language_model_file = options_.recognizer().language_model_file();
    c.phone_model_file = options_.recognizer().phone_model_file();
    c.keyword_threshold = options_.recognizer().keyword_threshold();
    auto created = SphinxRecognizer::Create(c);
    if (created.ok()) {
      recognizer_ = *std::move(created);
    } else {
      log::Warn("recognizer_unavailable", {{"error", std::string(created.status().message())}});
    }
  }
#endif
}

ProsodyServiceImpl::~ProsodyServiceImpl() = default;

StatusOr<PipelineResult> ProsodyServiceImpl::RunAnalysis(std::span<const float> mono, int sample_rate_hz,
                                                         const v1::AnalysisParams& params,
                                                         const v1::RecognizerParams& recognizer,
                                                         const CancelToken* cancel, std::string_view prefix,
                                                         PipelineRequest* p) {
  KINEMO_ASSIGN_OR_RETURN(p->options, ToAnalysisOptions(params, options_.defaults(), kinemo::StrCat(prefix, "params")));
  p->analysis_rate_hz = static_cast<int>(options_.analysis_rate_hz());
  p->recognize = recognizer.enabled();
  if (recognizer.keywords_size() > 100) {
    return InvalidField(kinemo::StrCat(prefix, "recognizer.keywords"), recognizer.keywords_size(),
                        " keywords (at most 100)");
  }
  for (const auto& k : recognizer.keywords()) p->keywords.push_back(k);
  p->keyword_threshold = recognizer.keyword_threshold();
  if (!(p->keyword_threshold >= 0)) {
    return InvalidField(kinemo::StrCat(prefix, "recognizer.keyword_threshold"), p->keyword_threshold,
                        " is negative (0 = the server's default)");
  }
  p->cancel = cancel;
  auto result = RunPipeline(mono, sample_rate_hz, *p, recognizer_.get());
  // Parameter errors name the option; report them as request fields.
  if (!result.ok()) return ToRequestFields(result.status(), kinemo::StrCat(prefix, "params"));
  return result;
}

void FillTrack(const PipelineResult& result, const PipelineRequest& p, bool include_frames,
               v1::ProsodyTrack* track) {
  const ProsodyResult& r = result.prosody;
  track->set_duration_s(r.duration_s);
  track->set_analysis_rate_hz(static_cast<uint32_t>(r.sample_rate_hz));
  track->set_frame_step_s(r.frame_step_s);
  track->set_first_frame_time_s(r.frames.empty() ? 0.0 : r.frames[0].time_s);
  if (include_frames) {
    for (const Frame& f : r.frames) FillFrame(f, track->add_frames());
  }
  for (const Syllable& s : r.syllables) FillSyllable(s, track->add_syllables());
  for (const Accent& a : r.accents) FillAccent(a, track->add_accents());
  for (const Pause& pz : r.pauses) {
    auto* out = track->add_pauses();
    out->set_start_s(pz.start_s);
    out->set_end_s(pz.end_s);
  }
  for (const Word& w : result.words) {
    auto* out = track->add_words();
    out->set_word(w.word);
    out->set_start_s(w.start_s);
    out->set_end_s(w.end_s);
    out->set_confidence(w.confidence);
    out->set_keyword(w.keyword);
  }
  for (const Phone& ph : result.phones) {
    auto* out = track->add_phones();
    out->set_phone(ph.phone);
    out->set_start_s(ph.start_s);
    out->set_end_s(ph.end_s);
  }
  track->set_recognizer_ran(result.recognizer_ran);
  FillParams(p.options, track->mutable_params());
}

void FillFace(const SpeechFaceFrame& f, v1::SpeechFaceFrame* out) {
  out->set_time_s(f.time_s);
  out->set_jaw_open_deg(f.jaw_open_deg);
  out->mutable_classes()->Add(f.classes.begin(), f.classes.end());
}

StatusOr<std::vector<float>> OfflineSpeechFaceFeatures(std::span<const float> mono, int sample_rate_hz) {
  if (sample_rate_hz == kFaceSampleRateHz) return OfflineFaceFeatures(mono);
  KINEMO_ASSIGN_OR_RETURN(const std::vector<float> at16k, audio::Resample(mono, sample_rate_hz, kFaceSampleRateHz));
  return OfflineFaceFeatures(at16k);
}

std::vector<SpeechFaceFrame> OfflineSpeechFace(std::vector<float> features, const FaceModel& model,
                                               const PipelineResult& result) {
  // With the recogniser's phones (recognizer.enabled) as a second opinion.
  std::vector<FacePhone> phones;
  phones.reserve(result.phones.size());
  for (const Phone& ph : result.phones) phones.push_back({ph.start_s, ph.end_s, ph.phone});
  return AnalyzeFaceFeatures(std::move(features), model, phones);
}

StatusOr<std::shared_ptr<const FaceModel>> ProsodyServiceImpl::FaceModelFor(const v1::FaceParams& params,
                                                                             std::string_view field) const {
  if (!params.model_id().empty()) {
    KINEMO_RETURN_IF_ERROR(store::ValidateId(params.model_id(), kinemo::StrCat(field, ".model_id")));
  }
  // No id: the bundled model if there is one, else no face (null).
  const std::string id = params.model_id().empty() ? "bundled" : params.model_id();
  const auto it = face_models_.find(id);
  if (it != face_models_.end()) return it->second;
  if (params.model_id().empty()) return std::shared_ptr<const FaceModel>();
  if (face_models_.empty() && options_.store_dir().empty()) {
    return absl::FailedPreconditionError(kinemo::StrCat(
        field, ".model_id: this prosody service has no store_dir, so no face models"));
  }
  return absl::NotFoundError(kinemo::StrCat(field, ".model_id: no face model '", id, "' in the store"));
}

grpc::ServerUnaryReactor* ProsodyServiceImpl::Analyze(grpc::CallbackServerContext* context,
                                                      const v1::AnalyzeRequest* request,
                                                      v1::AnalyzeResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const std::string id = RequestId(request->request_id(), next_request_id_);
  auto run = [this, context, request, response]() -> Status {
    // The caller's deadline and cancellation stop the analysis between stages.
    const std::unique_ptr<CancelToken> cancel = CallCancelToken(*context);
    KINEMO_RETURN_IF_ERROR(CheckCancel(cancel.get(), "analysis"));
    std::shared_ptr<const FaceModel> face;
    if (request->face().enabled()) {
      KINEMO_ASSIGN_OR_RETURN(face, FaceModelFor(request->face(), "face"));
    }
    KINEMO_ASSIGN_OR_RETURN(audio::DecodedAudio decoded,
                            DecodeRequestAudio(request->audio(), options_.max_audio_s()));
    PipelineRequest p;
    const auto t0 = std::chrono::steady_clock::now();
    KINEMO_ASSIGN_OR_RETURN(PipelineResult result,
                            RunAnalysis(decoded.samples, decoded.sample_rate_hz, request->params(),
                                        request->recognizer(), cancel.get(), "", &p));
    response->set_compute_s(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    FillTrack(result, p, !request->omit_frames(), response->mutable_track());
    if (face) {
      KINEMO_RETURN_IF_ERROR(CheckCancel(cancel.get(), "analysis"));
      KINEMO_ASSIGN_OR_RETURN(std::vector<float> features,
                              OfflineSpeechFaceFeatures(decoded.samples, decoded.sample_rate_hz));
      const std::vector<SpeechFaceFrame> frames = OfflineSpeechFace(std::move(features), *face, result);
      response->mutable_track()->mutable_face()->Reserve(static_cast<int>(frames.size()));
      for (const SpeechFaceFrame& f : frames) FillFace(f, response->mutable_track()->add_face());
    }
    return absl::OkStatus();
  };
  // The analysis runs on a worker (a long recording, or the recognizer, takes
  // seconds); gRPC's callback threads stay free.
  auto work = [reactor, response, id, run = std::move(run)]() {
    Status status = run();
    response->set_request_id(id);
    if (!status.ok()) {
      log::Info("analyze_failed", {{"request_id", id}, {"error", std::string(status.message())}});
    }
    reactor->Finish(ToGrpcStatus(status));
  };
  if (!workers_->Post(std::move(work))) {
    reactor->Finish(ToGrpcStatus(absl::ResourceExhaustedError(kinemo::StrCat(
        "worker_threads: ", workers_->threads(), " analyses running and too many queued; retry later"))));
  }
  return reactor;
}

namespace {

class StreamReactor final
    : public grpc::ServerBidiReactor<v1::StreamAnalyzeRequest, v1::StreamAnalyzeResponse> {
 public:
  StreamReactor(ProsodyServiceImpl* service, std::string default_id)
      : service_(service), id_(std::move(default_id)) {
    const int active = service_->active_streams().fetch_add(1) + 1;
    if (active > static_cast<int>(service_->options().max_concurrent_streams())) {
      FinishWith(absl::ResourceExhaustedError(kinemo::StrCat(
          "max_concurrent_streams: ", service_->options().max_concurrent_streams(),
          " streams already running")));
      return;
    }
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (finishing_) return;
    if (!ok) {
      // Half-close: flush and summarise.
      if (!analyzer_) {
        FinishLocked(InvalidField("config", "the stream ended before its config message"));
        return;
      }
      std::vector<float> tail;
      if (resampler_) (void)resampler_->Flush(tail);
      std::vector<StreamEvent> events;
      if (!tail.empty()) {
        Status s = analyzer_->Push(tail, &events);
        (void)s;
      }
      analyzer_->Finish(&events);
      Enqueue(events);
      (void)Recognize(/*finish=*/true);
      v1::StreamAnalyzeResponse summary;
      auto* sum = summary.mutable_summary();
      sum->set_duration_s(received_s_);
      sum->set_chunks(chunks_);
      sum->set_syllables(analyzer_->result().syllables.size());
      sum->set_accents(analyzer_->result().accents.size());
      sum->set_pauses(analyzer_->result().pauses.size());
      sum->set_words(WordsEmitted());
      summary.set_emitted_at_audio_s(received_s_);
      summary.set_last_chunk_sequence(chunks_ > 0 ? chunks_ - 1 : 0);
      queue_.push_back(std::move(summary));
      done_reading_ = true;
      pending_status_ = absl::OkStatus();
      MaybeWriteOrFinish();
      return;
    }
    Status s = Handle();
    if (!s.ok()) {
      FinishLocked(s);
      return;
    }
    MaybeWriteOrFinish();
    StartRead(&request_);
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mu_);
    writing_ = false;
    if (!ok) {
      if (!finishing_) {
        finishing_ = true;
        Finish(grpc::Status(grpc::StatusCode::CANCELLED, "client went away"));
      }
      return;
    }
    MaybeWriteOrFinish();
  }

  void OnDone() override {
    service_->active_streams().fetch_sub(1);
    delete this;
  }

 private:
  Status Handle() {
    if (request_.has_config()) {
      if (analyzer_) return InvalidField("config", "sent twice");
      const v1::StreamAnalyzeConfig& c = request_.config();
      if (!c.request_id().empty()) id_ = c.request_id();
      KINEMO_RETURN_IF_ERROR(CheckFormat(c.format(), "config.format", false));
      format_ = c.format();
      channels_ = std::max(1, static_cast<int>(format_.channels()));
      in_rate_ = static_cast<int>(format_.sample_rate_hz());
      const int rate = static_cast<int>(service_->options().analysis_rate_hz());
      KINEMO_RETURN_IF_ERROR(CheckRequestValues(c, "config"));
      KINEMO_ASSIGN_OR_RETURN(const AnalysisOptions options,
                              ToAnalysisOptions(c.params(), service_->options().defaults(), "config.params"));
      auto analyzer = StreamingAnalyzer::Create(rate, options, c.emit_frames());
      if (!analyzer.ok()) return ToRequestFields(analyzer.status(), "config.params");
      analyzer_ = *std::move(analyzer);
      if (in_rate_ != rate) {
        auto resampler = audio::StreamingResampler::Create(in_rate_, rate);
        if (!resampler.ok()) return resampler.status();
        resampler_ = std::make_unique<audio::StreamingResampler>(*std::move(resampler));
      }
      KINEMO_RETURN_IF_ERROR(OpenRecognizer(c.recognizer()));
      if (c.face().enabled()) {
        if (rate != kFaceSampleRateHz && !c.face().model_id().empty()) {
          return absl::FailedPreconditionError(kinemo::StrCat(
              "config.face.enabled: the live face needs analysis_rate_hz ", kFaceSampleRateHz, " (the server's is ", rate, ")"));
        }
        KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const FaceModel> model, service_->FaceModelFor(c.face(), "config.face"));
        if (model && rate == kFaceSampleRateHz) face_ = std::make_unique<FaceStream>(std::move(model));
        // Frame 0 (its window is before the stream) goes out with the first chunk.
      }
      v1::StreamAnalyzeResponse info;
      auto* i = info.mutable_info();
      i->set_analysis_rate_hz(rate);
      i->set_frame_latency_s(analyzer_->frame_latency_s());
      i->set_syllable_latency_s(analyzer_->syllable_latency_s());
      i->set_accent_latency_s(analyzer_->accent_latency_s());
      i->set_recognizer_running(RecognizerRunning());
      i->set_face_running(face_ != nullptr);
      i->set_request_id(id_);
      queue_.push_back(std::move(info));
      return absl::OkStatus();
    }
    if (!request_.has_chunk()) return InvalidField("message", "neither config nor chunk");
    if (!analyzer_) return InvalidField("config", "must be the first message");
    const common::v1::AudioChunk& chunk = request_.chunk();
    if (chunk.sequence_number() != chunks_) {
      return InvalidField("chunk.sequence_number", chunk.sequence_number(), " out of sequence (",
                          chunks_, " expected)");
    }
    const int bytes_per_frame = channels_ * (ToPcm(format_.encoding()) == audio::PcmEncoding::kF32Le ? 4 : 2);
    const double chunk_s =
        static_cast<double>(chunk.data().size()) / bytes_per_frame / in_rate_;
    if (chunk_s > service_->options().max_chunk_s()) {
      return InvalidField("chunk.data", chunk_s, " s of audio exceeds max_chunk_s (",
                          service_->options().max_chunk_s(), ")");
    }
    if (received_s_ + chunk_s > service_->options().max_stream_s()) {
      return InvalidField("chunk.data", "the stream exceeds max_stream_s (",
                          service_->options().max_stream_s(), " s)");
    }
    mono_.clear();
    const auto* data = reinterpret_cast<const std::uint8_t*>(chunk.data().data());
    KINEMO_RETURN_IF_ERROR(Annotate(
        audio::AppendPcmAsMono({data, chunk.data().size()}, ToPcm(format_.encoding()), channels_,
                               audio::NonFinitePolicy::kReject, mono_),
        "chunk.data"));
    ++chunks_;
    received_s_ += chunk_s;
    std::vector<StreamEvent> events;
    if (resampler_) {
      resampled_.clear();
      KINEMO_RETURN_IF_ERROR(resampler_->Process(mono_, resampled_));
      KINEMO_RETURN_IF_ERROR(analyzer_->Push(resampled_, &events));
    } else {
      KINEMO_RETURN_IF_ERROR(analyzer_->Push(mono_, &events));
    }
    // The face first: it needs nothing past this chunk, so it leaves first.
    if (face_) {
      face_frames_.clear();
      face_->Push(resampler_ ? std::span<const float>(resampled_) : std::span<const float>(mono_), &face_frames_);
      if (!face_frames_.empty()) {
        v1::StreamAnalyzeResponse r = NewEvent();
        auto* batch = r.mutable_face();
        for (const SpeechFaceFrame& f : face_frames_) FillFace(f, batch->add_frames());
        queue_.push_back(std::move(r));
        // On its way now, not after the recogniser has worked on the chunk.
        MaybeWriteOrFinish();
      }
    }
    Enqueue(events);
    return Recognize(/*finish=*/false);
  }

  // ---- Live recognition (CMU Sphinx, 16 kHz): keyword spotting
  // (config.recognizer.keywords) and timed phones (config.recognizer.enabled).
#ifdef KINEMO_WITH_SPHINX
  Status OpenRecognizer(const v1::RecognizerParams& r) {
    if (r.keywords_size() == 0 && !r.enabled()) return absl::OkStatus();
    if (r.keywords_size() > 100) return InvalidField("config.recognizer.keywords", r.keywords_size(), " keywords (at most 100)");
    if (!(r.keyword_threshold() >= 0)) {
      return InvalidField("config.recognizer.keyword_threshold", r.keyword_threshold(),
                          " is negative (0 = the server's default)");
    }
    SphinxRecognizer* recognizer = service_->recognizer();
    if (recognizer == nullptr) {
      return absl::FailedPreconditionError(kinemo::StrCat(
          "config.recognizer.", r.keywords_size() > 0 ? "keywords" : "enabled",
          ": the recognizer is not available on this server (disabled or models missing)"));
    }
    if (r.keywords_size() > 0) {
      auto stream = recognizer->OpenKeywordStream({r.keywords().begin(), r.keywords().end()}, r.keyword_threshold());
      if (!stream.ok()) {  // "keywords[1]: ..." -> "config.recognizer.keywords[1]: ..."
        return Status(stream.status().code(), kinemo::StrCat("config.recognizer.", stream.status().message()));
      }
      keywords_ = *std::move(stream);
    }
    if (r.enabled()) {
      auto stream = recognizer->OpenPhoneStream(kLivePhoneLagS);
      if (!stream.ok()) return Annotate(stream.status(), "config.recognizer.enabled");
      phones_ = *std::move(stream);
    }
    const int rate = static_cast<int>(service_->options().analysis_rate_hz());
    if (in_rate_ != SphinxRecognizer::kSampleRateHz && rate != SphinxRecognizer::kSampleRateHz) {
      auto resampler = audio::StreamingResampler::Create(in_rate_, SphinxRecognizer::kSampleRateHz);
      if (!resampler.ok()) return resampler.status();
      sphinx_resampler_ = std::make_unique<audio::StreamingResampler>(*std::move(resampler));
    }
    return absl::OkStatus();
  }
  bool RecognizerRunning() const { return keywords_ != nullptr || phones_ != nullptr; }
  uint64_t WordsEmitted() const { return keywords_spotted_; }
  // Feeds the last chunk (16 kHz: the input, the analysis audio, or its own
  // resampling; at the end, what the resampler still holds) to the keyword
  // spotter and the phone stream and queues what they found.
  Status Recognize(bool finish) {
    if (!RecognizerRunning()) return absl::OkStatus();
    const std::vector<float>* audio16k = &mono_;
    if (sphinx_resampler_) {
      sphinx_audio_.clear();
      KINEMO_RETURN_IF_ERROR(finish ? sphinx_resampler_->Flush(sphinx_audio_)
                                    : sphinx_resampler_->Process(mono_, sphinx_audio_));
      audio16k = &sphinx_audio_;
    } else if (finish) {
      sphinx_audio_.clear();  // the last chunk went in already
      audio16k = &sphinx_audio_;
    } else if (in_rate_ != SphinxRecognizer::kSampleRateHz) {
      audio16k = &resampled_;
    }
    std::vector<RecognizedWord> found;
    std::vector<RecognizedPhone> phones;
    if (keywords_) {
      KINEMO_RETURN_IF_ERROR(keywords_->Process(*audio16k, &found));
      if (finish) KINEMO_RETURN_IF_ERROR(keywords_->Finish(&found));
    }
    if (phones_) {
      KINEMO_RETURN_IF_ERROR(phones_->Process(*audio16k, &phones));
      if (finish) KINEMO_RETURN_IF_ERROR(phones_->Finish(&phones));
    }
    for (const RecognizedWord& w : found) {
      v1::StreamAnalyzeResponse r = NewEvent();
      auto* word = r.mutable_word();
      word->set_word(w.word);
      word->set_start_s(w.start_s);
      word->set_end_s(w.end_s);
      word->set_keyword(true);
      queue_.push_back(std::move(r));
      ++keywords_spotted_;
    }
    for (const RecognizedPhone& p : phones) {
      v1::StreamAnalyzeResponse r = NewEvent();
      auto* phone = r.mutable_phone();
      phone->set_phone(p.phone);
      phone->set_start_s(p.start_s);
      phone->set_end_s(p.end_s);
      queue_.push_back(std::move(r));
    }
    return absl::OkStatus();
  }
#else
  Status OpenRecognizer(const v1::RecognizerParams& r) {
    if (r.keywords_size() == 0 && !r.enabled()) return absl::OkStatus();
    return absl::FailedPreconditionError(kinemo::StrCat(
        "config.recognizer.", r.keywords_size() > 0 ? "keywords" : "enabled",
        ": this server was built without the recognizer (KINEMO_WITH_SPHINX=OFF)"));
  }
  bool RecognizerRunning() const { return false; }
  uint64_t WordsEmitted() const { return 0; }
  Status Recognize(bool) { return absl::OkStatus(); }
#endif

  // An event stamped with the audio received so far.
  v1::StreamAnalyzeResponse NewEvent() const {
    v1::StreamAnalyzeResponse r;
    r.set_emitted_at_audio_s(received_s_);
    r.set_last_chunk_sequence(chunks_ > 0 ? chunks_ - 1 : 0);
    return r;
  }

  void Enqueue(const std::vector<StreamEvent>& events) {
    for (const StreamEvent& e : events) {
      v1::StreamAnalyzeResponse r;
      r.set_emitted_at_audio_s(e.emitted_at_s);
      r.set_last_chunk_sequence(chunks_ > 0 ? chunks_ - 1 : 0);
      switch (e.kind) {
        case StreamEvent::Kind::kFrames:
          for (const Frame& f : e.frames) FillFrame(f, r.mutable_frames()->add_frames());
          break;
        case StreamEvent::Kind::kSyllable:
          FillSyllable(e.syllable, r.mutable_syllable());
          break;
        case StreamEvent::Kind::kAccent:
          FillAccent(e.accent, r.mutable_accent());
          break;
        case StreamEvent::Kind::kPauseStart:
        case StreamEvent::Kind::kPauseEnd:
          r.mutable_pause()->set_start_s(e.pause.start_s);
          r.mutable_pause()->set_end_s(e.pause.end_s);
          break;
      }
      queue_.push_back(std::move(r));
    }
  }

  void MaybeWriteOrFinish() {
    if (writing_ || finishing_) return;
    if (!queue_.empty()) {
      current_ = std::move(queue_.front());
      queue_.pop_front();
      writing_ = true;
      StartWrite(&current_);
      return;
    }
    if (done_reading_) {
      finishing_ = true;
      Finish(ToGrpcStatus(pending_status_));
    }
  }

  void FinishLocked(const Status& status) {
    // Errors end the call at once; queued events are dropped.
    queue_.clear();
    pending_status_ = status;
    done_reading_ = true;
    if (!writing_) {
      finishing_ = true;
      Finish(ToGrpcStatus(status));
    }
  }

  void FinishWith(const Status& status) {
    std::lock_guard<std::mutex> lock(mu_);
    FinishLocked(status);
  }

  ProsodyServiceImpl* service_;
  std::string id_;
  std::mutex mu_;
  v1::StreamAnalyzeRequest request_;
  v1::StreamAnalyzeResponse current_;
  std::deque<v1::StreamAnalyzeResponse> queue_;
  bool writing_ = false;
  bool finishing_ = false;
  bool done_reading_ = false;
  Status pending_status_;
  common::v1::AudioFormat format_;
  int channels_ = 1;
  int in_rate_ = 16000;
  uint64_t chunks_ = 0;
  double received_s_ = 0;
  std::unique_ptr<StreamingAnalyzer> analyzer_;
  std::unique_ptr<FaceStream> face_;  // config.face
  std::vector<SpeechFaceFrame> face_frames_;
  std::unique_ptr<audio::StreamingResampler> resampler_;
  std::vector<float> mono_;
  std::vector<float> resampled_;
#ifdef KINEMO_WITH_SPHINX
  std::unique_ptr<KeywordStream> keywords_;
  std::unique_ptr<PhoneStream> phones_;
  std::unique_ptr<audio::StreamingResampler> sphinx_resampler_;
  std::vector<float> sphinx_audio_;
  uint64_t keywords_spotted_ = 0;
#endif
};

}  // namespace

grpc::ServerBidiReactor<v1::StreamAnalyzeRequest, v1::StreamAnalyzeResponse>*
ProsodyServiceImpl::StreamAnalyze(grpc::CallbackServerContext* /*context*/) {
  return new StreamReactor(this, RequestId("", next_request_id_));
}

}  // namespace kinemo::prosody
