// ProsodyService.AnalyzeChunked: Analyze for a recording of any length, sent
// as PCM chunks; the track goes back without its frames, then the frames in
// batches, then the speech face (config.face) in batches (prosody.proto).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <vector>

#include "common/audio/resample.h"
#include "common/grpc/cancel_token.h"
#include "common/grpc/request_check.h"
#include "common/grpc/call_slot.h"
#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "services/prosody/core/face_model.h"
#include "services/prosody/prosody_service.h"

namespace kinemo::prosody {
namespace {
namespace analyze_chunked {  // this file's own helpers (the unity build puts files together)

// Frames per `frames` message: 10000 frames are about 300 kB.
constexpr std::size_t kFramesPerBatch = 10000;
// Speech-face frames per `face` message: 5000 are about 450 kB (18 class
// posteriors each).
constexpr std::size_t kFaceFramesPerBatch = 5000;

class ChunkedReactor final
    : public grpc::ServerBidiReactor<v1::AnalyzeChunkedRequest, v1::AnalyzeChunkedResponse> {
 public:
  ChunkedReactor(ProsodyServiceImpl* service, grpc::CallbackServerContext* context)
      : service_(service), context_(context) {
    // Admission: each call holds its recording until the analysis.
    const int limit = static_cast<int>(service_->options().max_concurrent_chunked());
    if (!slot_.Take(&service_->active_chunked(), limit)) {
      FinishOnce(absl::ResourceExhaustedError(
          kinemo::StrCat("max_concurrent_chunked: ", limit, " recordings are being analysed; retry later")));
      return;
    }
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client half-closed (or went away: the analysis sees the cancellation)
      if (!configured_) {
        FinishOnce(InvalidField("config", "the call ended before its config message"));
        return;
      }
      StartAnalysis();
      return;
    }
    if (Status s = Handle(); !s.ok()) {
      FinishOnce(s);
      return;
    }
    StartRead(&request_);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      FinishOnce(absl::CancelledError("the client went away"));
      return;
    }
    WriteNext();
  }

  void OnDone() override { delete this; }

 private:
  Status Handle() {
    if (request_.has_config()) {
      if (configured_) return InvalidField("config", "sent twice");
      const v1::AnalyzeChunkedConfig& c = request_.config();
      KINEMO_RETURN_IF_ERROR(CheckRequestValues(c, "config"));
      KINEMO_RETURN_IF_ERROR(CheckPcmFormat(c.format(), "config.format"));
      // Parameters are checked now, before the upload (they are used after it).
      KINEMO_RETURN_IF_ERROR(ToAnalysisOptions(c.params(), service_->options().defaults(), "config.params").status());
      if (!(c.expected_duration_s() >= 0)) {
        return InvalidField("config.expected_duration_s", c.expected_duration_s(), " must be >= 0 (0 = unknown)");
      }
      // The face model, before the upload: an unknown one fails now.
      if (c.face().enabled()) {
        KINEMO_ASSIGN_OR_RETURN(face_model_, service_->FaceModelFor(c.face(), "config.face"));
      }
      config_ = c;
      id_ = service_->NextRequestId(c.request_id());
      channels_ = std::max(1, static_cast<int>(c.format().channels()));
      in_rate_ = static_cast<int>(c.format().sample_rate_hz());
      encoding_ = PcmEncodingOf(c.format().encoding());
      rate_ = static_cast<int>(service_->options().analysis_rate_hz());
      if (in_rate_ != rate_) {
        KINEMO_ASSIGN_OR_RETURN(audio::StreamingResampler r, audio::StreamingResampler::Create(in_rate_, rate_));
        resampler_ = std::make_unique<audio::StreamingResampler>(std::move(r));
      }
      // Room for the whole recording at once when its length is known: the
      // buffer then never grows (growing copies it, twice the memory).
      const double expected_s = std::min(c.expected_duration_s(), service_->options().max_chunked_audio_s());
      samples_.reserve(static_cast<std::size_t>(std::ceil(expected_s * rate_)) + static_cast<std::size_t>(rate_));
      configured_ = true;
      return absl::OkStatus();
    }
    if (!request_.has_chunk()) return InvalidField("message", "neither config nor chunk");
    if (!configured_) return InvalidField("config", "must be the first message");
    const common::v1::AudioChunk& chunk = request_.chunk();
    if (chunk.sequence_number() != chunks_) {
      return InvalidField("chunk.sequence_number", chunk.sequence_number(), " out of sequence (", chunks_,
                          " expected)");
    }
    const std::size_t frame_bytes = static_cast<std::size_t>(channels_ * audio::BytesPerSample(encoding_));
    const double chunk_s = static_cast<double>(chunk.data().size() / frame_bytes) / in_rate_;
    if (chunk_s > service_->options().max_chunk_s()) {
      return InvalidField("chunk.data", chunk_s, " s of audio exceeds max_chunk_s (", service_->options().max_chunk_s(),
                          " s)");
    }
    if (received_s_ + chunk_s > service_->options().max_chunked_audio_s()) {
      return InvalidField("chunk", "the recording is longer than max_chunked_audio_s (",
                          service_->options().max_chunked_audio_s(), " s)");
    }
    const auto* data = reinterpret_cast<const std::uint8_t*>(chunk.data().data());
    if (resampler_) {
      mono_.clear();
      KINEMO_RETURN_IF_ERROR(Annotate(audio::AppendPcmAsMono({data, chunk.data().size()}, encoding_, channels_,
                                                             audio::NonFinitePolicy::kReject, mono_),
                                      "chunk.data"));
      KINEMO_RETURN_IF_ERROR(resampler_->Process(mono_, samples_));
    } else {
      KINEMO_RETURN_IF_ERROR(Annotate(audio::AppendPcmAsMono({data, chunk.data().size()}, encoding_, channels_,
                                                             audio::NonFinitePolicy::kReject, samples_),
                                      "chunk.data"));
    }
    ++chunks_;
    received_s_ += chunk_s;
    return absl::OkStatus();
  }

  // After the last chunk: the analysis on a worker, then the answers.
  void StartAnalysis() {
    auto work = [this] {
      const Status status = Analyze();
      if (!status.ok()) {
        log::Info("analyze_failed", {{"request_id", id_}, {"error", std::string(status.message())}});
        FinishOnce(status);
        return;
      }
      WriteNext();
    };
    if (!service_->workers().Post(std::move(work))) {
      FinishOnce(absl::ResourceExhaustedError(kinemo::StrCat("worker_threads: ", service_->workers().threads(),
                                                             " analyses running and too many queued; retry later")));
    }
  }

  Status Analyze() {
    const std::unique_ptr<CancelToken> cancel = CallCancelToken(*context_);
    KINEMO_RETURN_IF_ERROR(CheckCancel(cancel.get(), "analysis"));
    if (resampler_) KINEMO_RETURN_IF_ERROR(resampler_->Flush(samples_));
    if (samples_.empty()) return InvalidField("chunk", "no audio was sent (0 samples)");
    const auto t0 = std::chrono::steady_clock::now();
    PipelineRequest p;
    KINEMO_ASSIGN_OR_RETURN(result_, service_->RunAnalysis(samples_, rate_, config_.params(), config_.recognizer(),
                                                           cancel.get(), "config.", &p));
    // The speech face as Analyze makes it: the offline head over the whole
    // recording. Its features first, so that the audio's memory goes back
    // before the face's own (it is no longer needed: nor for the answers).
    std::vector<float> face_features;
    if (face_model_) {
      KINEMO_RETURN_IF_ERROR(CheckCancel(cancel.get(), "analysis"));
      KINEMO_ASSIGN_OR_RETURN(face_features, OfflineSpeechFaceFeatures(samples_, rate_));
    }
    std::vector<float>().swap(samples_);
    if (face_model_) {
      KINEMO_RETURN_IF_ERROR(CheckCancel(cancel.get(), "analysis"));
      face_ = OfflineSpeechFace(std::move(face_features), *face_model_, result_);
    }
    auto* r = first_.mutable_result();
    r->set_compute_s(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    r->set_request_id(id_);
    FillTrack(result_, p, /*include_frames=*/false, r->mutable_track());
    log::Debug("analyzed_chunked", {{"request_id", id_},
                                    {"name", config_.name()},
                                    {"duration_s", result_.prosody.duration_s},
                                    {"chunks", chunks_}});
    return absl::OkStatus();
  }

  // The result first, then the frames in batches, then the end.
  void WriteNext() {
    if (!result_sent_) {
      result_sent_ = true;
      StartWrite(&first_);
      return;
    }
    const auto& frames = result_.prosody.frames;
    if (!config_.omit_frames() && next_frame_ < frames.size()) {
      batch_.Clear();
      const std::size_t end = std::min(frames.size(), next_frame_ + kFramesPerBatch);
      for (; next_frame_ < end; ++next_frame_) FillFrame(frames[next_frame_], batch_.mutable_frames()->add_frames());
      StartWrite(&batch_);
      return;
    }
    if (next_face_ < face_.size()) {
      batch_.Clear();
      const std::size_t end = std::min(face_.size(), next_face_ + kFaceFramesPerBatch);
      auto* out = batch_.mutable_face()->mutable_frames();
      out->Reserve(static_cast<int>(end - next_face_));
      for (; next_face_ < end; ++next_face_) FillFace(face_[next_face_], out->Add());
      StartWrite(&batch_);
      return;
    }
    FinishOnce(absl::OkStatus());
  }

  // The slot is free again before the client hears the status (as the
  // coordinator's and the planner's chunked calls do): a client that starts
  // its next call on hearing it is not refused by its own finished call.
  void FinishOnce(const Status& status) {
    std::lock_guard<std::mutex> lock(finish_mu_);
    if (finished_) return;
    finished_ = true;
    slot_.Release();
    Finish(ToGrpcStatus(status));
  }

  ProsodyServiceImpl* service_;
  grpc::CallbackServerContext* context_;
  v1::AnalyzeChunkedRequest request_;
  v1::AnalyzeChunkedConfig config_;
  std::string id_;
  bool configured_ = false;
  CallSlot slot_;  // max_concurrent_chunked
  int channels_ = 1, in_rate_ = 16000, rate_ = 16000;
  audio::PcmEncoding encoding_ = audio::PcmEncoding::kS16Le;
  std::unique_ptr<audio::StreamingResampler> resampler_;
  std::uint64_t chunks_ = 0;
  double received_s_ = 0;
  std::vector<float> mono_;     // a chunk, mixed (before resampling)
  std::vector<float> samples_;  // the recording at the analysis rate
  PipelineResult result_;
  std::shared_ptr<const FaceModel> face_model_;  // config.face; null = no face
  std::vector<SpeechFaceFrame> face_;            // the speech face, sent after the frames
  v1::AnalyzeChunkedResponse first_, batch_;
  bool result_sent_ = false;
  std::size_t next_frame_ = 0, next_face_ = 0;
  std::mutex finish_mu_;
  bool finished_ = false;
};

}  // namespace analyze_chunked
}  // namespace

grpc::ServerBidiReactor<v1::AnalyzeChunkedRequest, v1::AnalyzeChunkedResponse>* ProsodyServiceImpl::AnalyzeChunked(
    grpc::CallbackServerContext* context) {
  return new analyze_chunked::ChunkedReactor(this, context);
}

}  // namespace kinemo::prosody
