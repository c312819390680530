// StreamAnimate on the callback API: one server reactor per stream and three
// client reactors for the downstream streams, driven by gRPC's callbacks
// under one mutex per stream (no thread of its own).
//
//   client chunk ──> prosody.StreamAnalyze ──> syllables, pauses ──> inference.StreamInfer
//        │                 │ keywords ──> planner; accents ──> client       │
//        │                                                                  v
//        └──> planner.Control advance_to_s (the audio clock) <── filtered beliefs
//   planner header / frames ──> client (audio_time_s, last_chunk_sequence)
//
// Every chunk advances media time to the end of the audio received, so the
// planner emits frames at the pace of the audio, through pauses too; the
// beliefs arrive later (syllables end, the CRF filters) and change what plays
// next (late beliefs, controller_rpcs.cc). When the client half-closes: the
// three streams are closed in order (the last frames), then, with
// config.visemes, prosody.Analyze runs the recogniser over the stream's audio
// and planner.Visemes makes the tracks, then a summary; then OK. The first
// error cancels everything and ends the call with it.
//
// With config.session_id the stream follows that session's Vleo (a cube
// attached with AttachCube): the stream subscribes to the session (outside
// its mutex: the manager calls subscribers under its own lock, and the
// stream never calls the manager under mu_), turns the current action and
// every ActionChanged into a style message to the planner
// (core/cube_tone.h), and counts the style messages it sends. The planner's
// decisions carry how many it had applied (ControlDecision.style_changes):
// the first decision at or past a change's count is the first made in its
// tone, and a tone_change goes to the client just before the frames that
// hold it.
//
// Flow control: the client's next message is read only while every queue
// (to the client, to prosody, to the planner) is short, so a client sending
// faster than real time is held to the pipeline's pace and memory per stream
// stays bounded.
//
// Idle timeout (deadlines.stream_idle_s, checked by the service's watchdog):
// a leg that owes an answer and has made no progress for that long ends the
// stream with DEADLINE_EXCEEDED naming the service. A leg owes: a write it
// started (the peer stopped reading), its first answer to its config (the
// planner's header, inference's model), frames once the audio clock passed
// the next frame (the planner), and its end after it was closed. Prosody may
// stay silent while it listens, and inference waits for its lookahead, so
// their silence alone is no fault.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "common/metrics/metrics.h"
#include "common/server/capacity.h"
#include "common/vmc/vmc_proto.h"
#include "services/coordinator/coordinator_service.h"
#include "services/coordinator/core/animate_plan.h"
#include "services/coordinator/core/cube_tone.h"
#include "services/coordinator/core/face_animate.h"
#include "services/coordinator/core/session_manager.h"
#include "services/coordinator/downstream.h"
#include "services/coordinator/idle_watchdog.h"

namespace kinemo::coordinator {
namespace {

namespace inf = ::kinemo::inference::v1;
namespace pl = ::kinemo::planner::v1;
namespace pr = ::kinemo::prosody::v1;

// The client's next message is read only while every queue is shorter.
constexpr std::size_t kMaxQueued = 32;
// Longest a frame batch waits for its face (docs/face.md): past it the batch
// goes with the face as far as the speech face reaches (the body never waits
// on a late prosody stream, e.g. one still starting its keyword spotter).
constexpr double kMaxFaceWaitS = 0.02;
// A batch whose last frame is further than this ahead of the speech face does
// not wait at all.
constexpr double kMaxFaceBehindS = 0.04;

enum LegId { kProsody = 0, kInference = 1, kControl = 2, kLegs = 3 };
constexpr const char* kLegNames[kLegs] = {"prosody", "inference", "planner"};

grpc::Status Refused(grpc::StatusCode code, const std::string& message) {
  return grpc::Status(code, CapMessage(message, kMaxStatusMessageBytes));
}

std::chrono::system_clock::time_point After(double s) {
  return std::chrono::system_clock::now() +
         std::chrono::microseconds(static_cast<std::int64_t>(s * 1e6));
}

class LiveStream;

// One downstream bidi stream, client side. Every method but the reactions
// runs under the owner's mutex. A hold keeps the call open while the owner
// may still write from other reactions; it is released with WritesDone or
// on cancellation.
template <typename Req, typename Resp>
class Leg final : public grpc::ClientBidiReactor<Req, Resp> {
 public:
  using Clock = std::chrono::steady_clock;
  Leg(std::shared_ptr<LiveStream> owner, LegId id, std::unique_ptr<grpc::ClientContext> context)
      : owner_(std::move(owner)), id_(id), context_(std::move(context)) {}
  grpc::ClientContext* context() { return context_.get(); }
  // After the stub's async() call has bound this reactor.
  void Begin() {
    this->StartRead(&in_);
    this->AddHold();
    this->StartCall();
  }
  // `owes`: the peer owes an answer to it (see the idle timeout).
  void Send(Req r, bool owes = false) {
    if (closing_) return;
    out_.push_back(std::move(r));
    if (owes) Owe();
  }
  // WritesDone once the queued messages are written; the peer then owes its end.
  void Close() {
    closing_ = true;
    Owe();
  }
  // Since when the leg owes progress (none: Clock::time_point::max()).
  Clock::time_point stalled_since() const { return std::min(writing_ ? write_since_ : Clock::time_point::max(), owed_since_); }
  bool closing() const { return closing_; }
  void Cancel() {
    cancelled_ = true;
    context_->TryCancel();
    ReleaseHold();
  }
  std::size_t queued() const { return out_.size(); }
  void Pump() {
    if (cancelled_ || broken_) return;
    if (!writing_ && !out_.empty()) {
      writing_ = true;
      write_since_ = Clock::now();
      this->StartWrite(&out_.front());
    } else if (closing_ && !writing_ && out_.empty() && !writes_done_) {
      writes_done_ = true;
      this->StartWritesDone();
      ReleaseHold();
    }
  }

 private:
  void OnReadDone(bool ok) override;
  void OnWriteDone(bool ok) override;
  void OnDone(const grpc::Status& status) override;
  void ReleaseHold() {
    if (hold_released_) return;
    hold_released_ = true;
    this->RemoveHold();
  }
  void Owe() { owed_since_ = std::min(owed_since_, Clock::now()); }

  std::shared_ptr<LiveStream> owner_;
  const LegId id_;
  std::unique_ptr<grpc::ClientContext> context_;
  Resp in_;
  std::deque<Req> out_;  // front: being written
  bool writing_ = false, closing_ = false, writes_done_ = false;
  bool cancelled_ = false, broken_ = false, hold_released_ = false;
  Clock::time_point write_since_;                            // the write in flight started
  Clock::time_point owed_since_ = Clock::time_point::max();  // the oldest answer owed
};

using ProsodyLeg = Leg<pr::StreamAnalyzeRequest, pr::StreamAnalyzeResponse>;
using InferenceLeg = Leg<inf::StreamInferRequest, inf::StreamInferResponse>;
using ControlLeg = Leg<pl::ControlRequest, pl::ControlResponse>;

// What a stream needs from the service.
struct LiveDeps {
  const v1::CoordinatorOptions* options;
  pr::ProsodyService::Stub* prosody;
  inf::InferenceService::Stub* inference;
  pl::PlannerService::Stub* planner;
  std::atomic<int>* streams;
  const Deadlines* deadlines;  // the visemes' calls (analysis), the legs' idle timeout
  Watchdog* watchdog;
  std::uint64_t max_message_bytes;                // the channels' limit
  SessionManager* sessions;                       // config.session_id
};

// Motion lag at the coordinator: a chunk of audio received → the frames
// that reach its end queued for the client (the client's own figure adds
// the network both ways).
prometheus::Histogram& MotionLag() {
  static auto& h = metrics::Histogram(
      "kinemo_stream_animate_motion_lag_seconds",
      "StreamAnimate: audio chunk received by the coordinator -> frames up to its end sent to the client.",
      {0.01, 0.025, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1, 2, 5});
  return h;
}

// When each recent chunk arrived, by the audio time it ends at: a fixed ring
// (no allocation per chunk); past kChunks unanswered chunks the oldest are
// forgotten.
class ChunkArrivals {
 public:
  void Add(double audio_end_s) {
    if (size_ == kChunks) Pop();
    ring_[(head_ + size_) % kChunks] = {audio_end_s, std::chrono::steady_clock::now()};
    ++size_;
  }
  // Frames up to `frame_s` leave now: observe the lag of every chunk they
  // complete.
  void FramesUpTo(double frame_s) {
    const auto now = std::chrono::steady_clock::now();
    while (size_ > 0 && ring_[head_].audio_end_s <= frame_s + 1e-9) {
      MotionLag().Observe(std::chrono::duration<double>(now - ring_[head_].at).count());
      Pop();
    }
  }

 private:
  static constexpr std::size_t kChunks = 256;
  struct Arrival {
    double audio_end_s = 0;
    std::chrono::steady_clock::time_point at;
  };
  void Pop() {
    head_ = (head_ + 1) % kChunks;
    --size_;
  }
  std::array<Arrival, kChunks> ring_{};
  std::size_t head_ = 0, size_ = 0;
};

class LiveStream final
    : public grpc::ServerBidiReactor<v1::StreamAnimateRequest, v1::StreamAnimateResponse> {
 public:
  static LiveStream* Start(grpc::CallbackServerContext* context, const LiveDeps& deps) {
    std::shared_ptr<LiveStream> s(new LiveStream(context, deps));
    s->self_ = s;
    std::lock_guard<std::mutex> l(s->mu_);
    s->reading_ = true;
    s->StartRead(&s->in_);
    return s.get();
  }
  ~LiveStream() override {
    if (counted_) deps_.streams->fetch_sub(1);
  }
  // The idle timeout (the watchdog's thread); false once over.
  bool CheckIdle(std::chrono::steady_clock::time_point now) {
    std::lock_guard<std::mutex> l(mu_);
    if (finished_ || !error_.ok()) return false;
    const auto idle = std::chrono::duration<double>(deps_.deadlines->stream_idle_s);
    auto check = [&](auto* leg, LegId id) {
      if (leg == nullptr || now - leg->stalled_since() < idle) return false;
      Fail(Refused(grpc::StatusCode::DEADLINE_EXCEEDED,
                   absl::StrCat(kLegNames[id], ": no progress on its stream for ", deps_.deadlines->stream_idle_s,
                                " s (deadlines.stream_idle_s)")));
      return true;
    };
    if (check(prosody_, kProsody) || check(inference_, kInference) || check(control_, kControl)) {
      Pump();
      return false;
    }
    return true;
  }

  // ---- server reactions ----
  void OnReadDone(bool ok) override {
    std::shared_ptr<LiveStream> subscribe;  // keeps the stream alive through SubscribeSession
    {
      std::lock_guard<std::mutex> l(mu_);
      reading_ = false;
      if (finished_) return;
      if (!ok) {
        OnClientHalfClose();
      } else if (!configured_) {
        Configure();
        if (configured_ && !config_.session_id().empty()) subscribe = self_;
      } else {
        OnClientMessage();
      }
      Pump();
    }
    if (subscribe != nullptr) SubscribeSession(subscribe);  // outside mu_ (see the top)
  }
  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> l(mu_);
    writing_ = false;
    to_client_.pop_front();
    if (!ok) Fail(grpc::Status(grpc::StatusCode::CANCELLED, "client went away"));
    Pump();
  }
  void OnCancel() override {
    std::lock_guard<std::mutex> l(mu_);
    Fail(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled by the client"));
    Pump();
  }
  void OnDone() override {
    std::shared_ptr<LiveStream> last;
    std::uint64_t subscription = 0;
    {
      std::lock_guard<std::mutex> l(mu_);
      last = std::move(self_);  // freed when the last leg or callback lets go
      subscription = std::exchange(subscription_, 0);
      unsubscribed_ = true;
    }
    if (subscription != 0) deps_.sessions->Unsubscribe(subscription);
  }

  // ---- from the legs (under mu_) ----
  std::mutex& mu() { return mu_; }
  void OnLegMessage(pr::StreamAnalyzeResponse& r);
  void OnLegMessage(inf::StreamInferResponse& r);
  void OnLegMessage(pl::ControlResponse& r);
  void OnLegDone(LegId id, const grpc::Status& status);
  void Pump();
  // A session event (the manager's thread, its lock held; mu_ not held).
  void OnSessionEvent(const v1::SessionEvent& e);

 private:
  LiveStream(grpc::CallbackServerContext* context, const LiveDeps& deps)
      : context_(context), deps_(deps) {}

  void Configure();
  void SubscribeSession(const std::shared_ptr<LiveStream>& self);
  void SendStyle(common::v1::Action action, double intensity);
  void OnDecision(const pl::ControlDecision& d);
  // Frame batches go to the client once their face is known (face_).
  void SendFrames(v1::StreamAnimateResponse frames);
  void FlushFaceFrames();
  void OnClientMessage();
  void OnClientHalfClose();
  void StartVisemes();
  void OnAnalyzed(const grpc::Status& s);
  void OnVisemes(const grpc::Status& s);
  void MaybeEnd();
  void Fail(const grpc::Status& s);
  void ToClient(v1::StreamAnimateResponse r);
  std::unique_ptr<grpc::ClientContext> LegContext() const;
  bool leg_done(LegId id) const {
    return id == kProsody ? prosody_ == nullptr : id == kInference ? inference_ == nullptr : control_ == nullptr;
  }

  grpc::CallbackServerContext* const context_;
  const LiveDeps deps_;
  std::mutex mu_;
  std::shared_ptr<LiveStream> self_;  // until OnDone

  // Server side.
  v1::StreamAnimateRequest in_;
  std::deque<v1::StreamAnimateResponse> to_client_;  // front: being written
  bool reading_ = false, writing_ = false, finished_ = false;
  bool configured_ = false, counted_ = false, client_closed_ = false, ended_ = false;
  grpc::Status error_;  // the first error

  // The pipeline.
  v1::StreamAnimateConfig config_;
  std::string request_id_;
  std::optional<AudioClock> clock_;
  ProsodyLeg* prosody_ = nullptr;  // null once done
  InferenceLeg* inference_ = nullptr;
  ControlLeg* control_ = nullptr;
  bool legs_started_ = false;
  double covered_s_ = 0;  // end of the last inference step sent
  double frame_time_s_ = 0, last_frame_s_ = 0;
  ChunkArrivals arrivals_;  // for the motion lag metric
  std::uint64_t frames_ = 0, beliefs_ = 0, decisions_ = 0;
  pr::StreamSummary prosody_summary_;

  // The face (docs/face.md): asked of prosody with every stream; until
  // prosody's StreamInfo says whether it runs, and then until the speech face
  // reaches their time, frame batches wait in held_frames_.
  std::optional<LiveFace> face_;
  bool face_known_ = false;  // prosody's StreamInfo arrived
  std::deque<v1::StreamAnimateResponse> held_frames_;
  std::deque<std::chrono::steady_clock::time_point> held_since_;  // when each held batch came
  double sent_frame_s_ = -1;  // time of the last frame sent to the client

  // The session's Vleo (config.session_id).
  struct PendingTone {
    std::uint64_t style_changes = 0;  // the planner's count once it applied this one
    v1::ToneChange change;
  };
  CubeToneMap cube_tones_;
  double cube_emphasis_gain_ = kDefaultCubeEmphasisGain;  // animate.cube_emphasis_gain
  std::uint64_t subscription_ = 0;
  bool unsubscribed_ = false;
  std::uint64_t styles_sent_ = 0;          // style messages sent to the planner
  std::deque<PendingTone> pending_tones_;  // sent, no decision in them yet
  std::vector<v1::ToneChange> ready_tones_;  // go out before the next frames
  std::string last_tone_;
  double last_weight_ = -1;
  double last_emphasis_ = 0;

  // config.vmc: the frames also go out as VMC packets (ToClient).
  std::unique_ptr<vmc::ProtoVmcStream> vmc_;

  // Visemes at the end (prosody.Analyze, then planner.Visemes).
  std::string audio_;  // the stream's PCM, with config.visemes
  bool unary_pending_ = false, visemes_ready_ = false;
  std::unique_ptr<grpc::ClientContext> unary_context_;
  pr::AnalyzeRequest analyze_request_;
  pr::AnalyzeResponse analyze_response_;
  pl::VisemesRequest visemes_request_;
  pl::VisemesResponse visemes_response_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

// ---- the legs' reactions -----------------------------------------------------

template <typename Req, typename Resp>
void Leg<Req, Resp>::OnReadDone(bool ok) {
  std::lock_guard<std::mutex> l(owner_->mu());
  if (ok) {
    // Progress: nothing owed (but the end, once closed).
    owed_since_ = closing_ ? Clock::now() : Clock::time_point::max();
    owner_->OnLegMessage(in_);
    if (!cancelled_) this->StartRead(&in_);
  } else {
    // The server ended the call (its status is on the way): let OnDone come.
    broken_ = true;
    ReleaseHold();
  }
  owner_->Pump();
}

template <typename Req, typename Resp>
void Leg<Req, Resp>::OnWriteDone(bool ok) {
  std::lock_guard<std::mutex> l(owner_->mu());
  writing_ = false;
  out_.pop_front();
  if (!ok) {  // the call is over; OnDone tells why
    broken_ = true;
    ReleaseHold();
  }
  owner_->Pump();
}

template <typename Req, typename Resp>
void Leg<Req, Resp>::OnDone(const grpc::Status& status) {
  std::shared_ptr<LiveStream> owner = std::move(owner_);
  {
    std::lock_guard<std::mutex> l(owner->mu());
    owner->OnLegDone(id_, status);
    owner->Pump();
  }
  delete this;
}

// ---- the stream --------------------------------------------------------------

std::unique_ptr<grpc::ClientContext> LiveStream::LegContext() const {
  // The client's deadline and cancellation carry over; a stream lasts at most
  // animate.max_audio_s of audio, so twice that (plus a minute) bounds it.
  auto c = grpc::ClientContext::FromCallbackServerContext(*context_);
  const double max_audio_s =
      deps_.options->animate().max_audio_s() > 0 ? deps_.options->animate().max_audio_s() : 600;
  c->set_deadline(After(2 * max_audio_s + 60));
  return c;
}

void LiveStream::Configure() {
  if (!in_.has_config()) {
    return Fail(Refused(grpc::StatusCode::INVALID_ARGUMENT, "config: must be the first message"));
  }
  config_ = std::move(*in_.mutable_config());
  const v1::CoordinatorOptions& o = *deps_.options;
  auto method = ResolveMethod(config_.method(), v1::METHOD_GESTURE_CONTROLLER, "config.method");
  if (!method.ok()) return Fail(ToGrpcStatus(method.status()));
  if (*method != v1::METHOD_GESTURE_CONTROLLER) {
    return Fail(Refused(grpc::StatusCode::INVALID_ARGUMENT,
                        "config.method: only METHOD_GESTURE_CONTROLLER runs live (GMG and "
                        "BodySpeech need the whole utterance; use Animate)"));
  }
  const double max_audio_s = o.animate().max_audio_s() > 0 ? o.animate().max_audio_s() : 600;
  auto clock = AudioClock::Create(config_.format(), max_audio_s, "config.format");
  if (!clock.ok()) return Fail(ToGrpcStatus(clock.status()));
  clock_ = *clock;
  if (deps_.prosody == nullptr) return Fail(Unavailable("prosody"));
  if (deps_.inference == nullptr) return Fail(Unavailable("inference"));
  if (deps_.planner == nullptr) return Fail(Unavailable("planner"));
  const auto& dm = o.animate().models();
  const std::string model_id = config_.models().inference_model_id().empty()
                                   ? dm.inference_model_id()
                                   : config_.models().inference_model_id();
  const std::string controller_id = config_.models().controller_id().empty()
                                        ? dm.controller_id()
                                        : config_.models().controller_id();
  if (model_id.empty() || controller_id.empty()) {
    return Fail(Refused(grpc::StatusCode::FAILED_PRECONDITION,
                        absl::StrCat(model_id.empty() ? "config.models.inference_model_id"
                                                      : "config.models.controller_id",
                                     ": not set, and no default in CoordinatorOptions.animate.models")));
  }
  if (!config_.vmc().address().empty()) {
    // (A name in config.vmc.address is resolved here, once.)
    const auto& allowed = o.animate().vmc_allowed_hosts();
    auto opened = vmc::OpenVmcTarget(config_.vmc(), {allowed.begin(), allowed.end()}, "config.vmc");
    if (!opened.ok()) return Fail(ToGrpcStatus(opened.status()));
    vmc_ = *std::move(opened);
  }
  const int max_streams = o.animate().max_concurrent_streams() > 0
                              ? static_cast<int>(o.animate().max_concurrent_streams())
                              : server::DefaultLiveStreamLimit();
  if (deps_.streams->fetch_add(1) >= max_streams) {
    deps_.streams->fetch_sub(1);
    return Fail(Refused(grpc::StatusCode::RESOURCE_EXHAUSTED,
                        absl::StrCat("StreamAnimate: ", max_streams,
                                     " streams open (animate.max_concurrent_streams)")));
  }
  if (!config_.session_id().empty()) {
    if (deps_.sessions == nullptr) return Fail(Unavailable("sessions"));
    auto tones = MakeCubeToneMap(o.animate().cube_tones(), "animate.cube_tones", config_.cube_tones(),
                                 "config.cube_tones");
    if (!tones.ok()) return Fail(ToGrpcStatus(tones.status()));
    cube_tones_ = *std::move(tones);
    if (o.animate().has_cube_emphasis_gain()) {
      const Status g = ValidateCubeEmphasisGain(o.animate().cube_emphasis_gain(), "animate.cube_emphasis_gain");
      if (!g.ok()) return Fail(ToGrpcStatus(g));
      cube_emphasis_gain_ = o.animate().cube_emphasis_gain();
    }
  } else if (!config_.cube_tones().empty()) {
    return Fail(Refused(grpc::StatusCode::INVALID_ARGUMENT, "config.cube_tones: needs config.session_id"));
  }
  counted_ = true;
  request_id_ = config_.request_id().empty()
                    ? absl::StrCat("stream-", std::chrono::system_clock::now().time_since_epoch().count())
                    : config_.request_id();

  // The three downstream streams, each with its config first.
  prosody_ = new ProsodyLeg(self_, kProsody, LegContext());
  inference_ = new InferenceLeg(self_, kInference, LegContext());
  control_ = new ControlLeg(self_, kControl, LegContext());
  deps_.prosody->async()->StreamAnalyze(prosody_->context(), prosody_);
  deps_.inference->async()->StreamInfer(inference_->context(), inference_);
  deps_.planner->async()->Control(control_->context(), control_);
  pr::StreamAnalyzeRequest pc;
  *pc.mutable_config()->mutable_format() = config_.format();
  *pc.mutable_config()->mutable_params() = config_.prosody_params();
  // Live keyword spotting takes the keywords alone (the full recogniser
  // needs whole utterances).
  *pc.mutable_config()->mutable_recognizer()->mutable_keywords() = config_.keywords();
  pc.mutable_config()->set_request_id(request_id_);
  pc.mutable_config()->mutable_face()->set_enabled(true);
  pc.mutable_config()->mutable_face()->set_model_id(config_.face_model_id());
  face_.emplace(0.0);
  prosody_->Send(std::move(pc));
  inf::StreamInferRequest ic;
  ic.mutable_config()->set_model_id(model_id);
  ic.mutable_config()->set_request_id(request_id_);
  inference_->Send(std::move(ic), /*owes=*/true);  // the model
  pl::ControlRequest cc;
  cc.mutable_config()->set_controller_id(controller_id);
  cc.mutable_config()->set_rig_id(config_.models().rig_id());
  *cc.mutable_config()->mutable_style() = config_.style();
  cc.mutable_config()->set_emit_decisions(true);  // counted for the summary
  cc.mutable_config()->set_request_id(request_id_);
  control_->Send(std::move(cc), /*owes=*/true);  // the header
  prosody_->Begin();
  inference_->Begin();
  control_->Begin();
  legs_started_ = true;
  if (deps_.watchdog != nullptr) {
    deps_.watchdog->Add([weak = std::weak_ptr<LiveStream>(self_)](std::chrono::steady_clock::time_point now) {
      const std::shared_ptr<LiveStream> s = weak.lock();
      return s != nullptr && s->CheckIdle(now);
    });
  }
  configured_ = true;
}

void LiveStream::OnClientMessage() {
  if (!error_.ok()) return;
  if (in_.has_chunk()) {
    if (config_.visemes() && audio_.size() + in_.chunk().data().size() + (64 << 10) > deps_.max_message_bytes) {
      return Fail(Refused(grpc::StatusCode::INVALID_ARGUMENT,
                          absl::StrCat("chunk: with config.visemes the stream's audio goes to the recogniser in one "
                                       "message, at most ", deps_.max_message_bytes,
                                       " bytes (server.max_message_bytes); ", audio_.size(), " bytes so far")));
    }
    if (Status s = clock_->Add(in_.chunk()); !s.ok()) return Fail(ToGrpcStatus(s));
    if (config_.visemes()) audio_.append(in_.chunk().data());
    arrivals_.Add(clock_->audio_s());
    pr::StreamAnalyzeRequest q;
    *q.mutable_chunk() = std::move(*in_.mutable_chunk());
    prosody_->Send(std::move(q));
    // The audio clock: frames up to the audio received.
    pl::ControlRequest a;
    a.set_advance_to_s(clock_->audio_s());
    // Frames are owed once the audio passed the frame after the last one.
    const bool owes = frame_time_s_ > 0 && clock_->audio_s() >= last_frame_s_ + 2 * frame_time_s_;
    control_->Send(std::move(a), owes);
    FlushFaceFrames();  // overdue batches go
  } else if (in_.has_style()) {
    pl::ControlRequest q;
    *q.mutable_style() = std::move(*in_.mutable_style());
    control_->Send(std::move(q));
    ++styles_sent_;
  } else if (in_.has_config()) {
    Fail(Refused(grpc::StatusCode::INVALID_ARGUMENT, "config: sent twice"));
  } else {
    Fail(Refused(grpc::StatusCode::INVALID_ARGUMENT, "message: neither chunk nor style"));
  }
}

void LiveStream::OnClientHalfClose() {
  client_closed_ = true;
  if (!configured_ || !error_.ok()) {
    ended_ = true;  // closed before its config: nothing to do
    return;
  }
  prosody_->Close();
  if (config_.visemes()) StartVisemes();
}

void LiveStream::OnLegMessage(pr::StreamAnalyzeResponse& r) {
  if (!error_.ok()) return;
  auto steps = [&](std::vector<inf::ProsodyFeatures> v) {
    for (auto& f : v) {
      inf::StreamInferRequest q;
      *q.mutable_features() = std::move(f);
      inference_->Send(std::move(q));
    }
  };
  if (r.has_syllable()) {
    auto v = GapSteps(covered_s_, r.syllable().start_s());
    v.push_back(SyllableStep(r.syllable()));
    covered_s_ = std::max(covered_s_, r.syllable().end_s());
    steps(std::move(v));
  } else if (r.has_pause()) {
    steps(GapSteps(covered_s_, r.pause().end_s()));
    covered_s_ = std::max(covered_s_, r.pause().end_s());
  } else if (r.has_accent()) {
    if (face_) face_->AddAccent(r.accent());
    if (config_.emit_prosody_events()) {
      v1::StreamAnimateResponse out;
      *out.mutable_accent() = std::move(*r.mutable_accent());
      ToClient(std::move(out));
    }
  } else if (r.has_word()) {
    if (!r.word().keyword()) return;
    pl::ControlRequest k;
    *k.mutable_keyword() = r.word();
    control_->Send(std::move(k));
    if (config_.emit_prosody_events()) {
      v1::StreamAnimateResponse out;
      *out.mutable_keyword() = std::move(*r.mutable_word());
      ToClient(std::move(out));
    }
  } else if (r.has_summary()) {
    prosody_summary_ = r.summary();
  } else if (r.has_info()) {
    face_known_ = true;
    if (!r.info().face_running()) face_.reset();
    FlushFaceFrames();
  } else if (r.has_face()) {
    if (face_) face_->AddSpeech(r.face());
    FlushFaceFrames();
  }
}

void LiveStream::OnLegMessage(inf::StreamInferResponse& r) {
  if (!error_.ok() || !r.has_filtered()) return;
  pl::ControlRequest q;
  *q.mutable_belief() = ToBeliefStep(r.filtered());
  // Never past the audio received: beliefs change what plays next, the
  // audio clock alone moves media time.
  auto* b = q.mutable_belief();
  b->set_end_s(std::min(b->end_s(), clock_->audio_s()));
  b->set_start_s(std::min(b->start_s(), b->end_s()));
  ++beliefs_;
  control_->Send(std::move(q));
}

void LiveStream::OnLegMessage(pl::ControlResponse& r) {
  if (!error_.ok()) return;
  v1::StreamAnimateResponse out;
  if (r.has_header()) {
    frame_time_s_ = r.header().frame_time_s();
    if (face_) face_->SetSkeleton(r.header().skeleton());
    *out.mutable_header() = std::move(*r.mutable_header());
  } else if (r.has_frames()) {
    const int n = r.frames().frames_size();
    if (n == 0) return;
    frames_ += static_cast<std::uint64_t>(n);
    last_frame_s_ = r.frames().frames(n - 1).time_s();
    *out.mutable_frames() = std::move(*r.mutable_frames());
    return SendFrames(std::move(out));
  } else {
    if (r.has_decision()) {
      ++decisions_;
      OnDecision(r.decision());
    }
    return;
  }
  ToClient(std::move(out));
}

void LiveStream::SendFrames(v1::StreamAnimateResponse out) {
  held_frames_.push_back(std::move(out));
  held_since_.push_back(std::chrono::steady_clock::now());
  FlushFaceFrames();
}

void LiveStream::FlushFaceFrames() {
  while (!held_frames_.empty()) {
    v1::StreamAnimateResponse& out = held_frames_.front();
    const auto& frames = out.frames().frames();
    // A batch leaves once the speech face reaches its last frame, or after
    // kMaxFaceWaitS with the face as far as it is known.
    const bool overdue =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - held_since_.front()).count() >= kMaxFaceWaitS;
    if (face_) {
      // Wait only for a speech face that is about to arrive: one more than
      // kMaxFaceBehindS behind the frame (a prosody stream still starting)
      // is not waited for.
      const double t = frames[frames.size() - 1].time_s();
      const bool far_behind = t - face_->speech_until_s() > kMaxFaceBehindS;
      if (!overdue && !far_behind && (!face_known_ || !face_->Ready(t))) return;
      for (auto& f : *out.mutable_frames()->mutable_frames()) face_->Fill(&f);
    } else if (!face_known_ && !overdue) {
      return;
    }
    sent_frame_s_ = frames[frames.size() - 1].time_s();
    arrivals_.FramesUpTo(sent_frame_s_ + frame_time_s_);
    for (auto& t : ready_tones_) {
      v1::StreamAnimateResponse tc;
      *tc.mutable_tone_change() = std::move(t);
      ToClient(std::move(tc));
    }
    ready_tones_.clear();
    ToClient(std::move(out));
    held_frames_.pop_front();
    held_since_.pop_front();
  }
}

void LiveStream::SubscribeSession(const std::shared_ptr<LiveStream>& self) {
  // config_ is not written after Configure.
  auto id = deps_.sessions->Subscribe(config_.session_id(), [weak = std::weak_ptr<LiveStream>(self)](
                                                                const v1::SessionEvent& e) {
    if (const std::shared_ptr<LiveStream> s = weak.lock()) s->OnSessionEvent(e);
  });
  bool drop = false;  // the stream ended meanwhile: nothing will unsubscribe later
  {
    std::lock_guard<std::mutex> l(mu_);
    if (!id.ok()) {
      Fail(ToGrpcStatus(Annotate(id.status(), "config.session_id")));
    } else if (unsubscribed_) {
      drop = true;
    } else {
      subscription_ = *id;
    }
    Pump();
  }
  if (drop) deps_.sessions->Unsubscribe(*id);
}

void LiveStream::OnSessionEvent(const v1::SessionEvent& e) {
  std::lock_guard<std::mutex> l(mu_);
  if (finished_ || !error_.ok() || control_ == nullptr || control_->closing()) return;
  if (e.has_snapshot()) {
    SendStyle(e.snapshot().action(), e.snapshot().intensity());
    if (!pending_tones_.empty()) pending_tones_.back().change.set_initial(true);
  } else if (e.has_action_changed()) {
    SendStyle(e.action_changed().action(), e.action_changed().intensity());
  } else {
    return;
  }
  Pump();
}

void LiveStream::SendStyle(common::v1::Action action, double intensity) {
  CubeStyle cs = StyleForAction(cube_tones_, action, intensity, cube_emphasis_gain_);
  if (cs.tone == last_tone_ && std::abs(cs.weight - last_weight_) < 1e-9 &&
      std::abs(cs.emphasis - last_emphasis_) < 1e-9)
    return;  // no change
  last_tone_ = cs.tone;
  last_weight_ = cs.weight;
  last_emphasis_ = cs.emphasis;
  PendingTone p;
  p.change.set_tone(cs.tone);
  p.change.set_weight(cs.weight);
  p.change.set_gesture_emphasis(cs.emphasis);
  *p.change.mutable_style() = cs.style;
  p.change.set_action(action);
  p.change.set_intensity(intensity);
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  p.change.mutable_seen_time()->set_seconds(std::chrono::duration_cast<std::chrono::seconds>(now).count());
  p.change.mutable_seen_time()->set_nanos(static_cast<int>(std::chrono::duration_cast<std::chrono::nanoseconds>(now).count() % 1000000000));
  pl::ControlRequest q;
  *q.mutable_style() = std::move(cs.style);
  control_->Send(std::move(q));
  p.style_changes = ++styles_sent_;
  pending_tones_.push_back(std::move(p));
}

void LiveStream::OnDecision(const pl::ControlDecision& d) {
  if (pending_tones_.empty() || d.style_changes() < pending_tones_.front().style_changes) return;
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  while (!pending_tones_.empty() && d.style_changes() >= pending_tones_.front().style_changes) {
    v1::ToneChange c = std::move(pending_tones_.front().change);
    pending_tones_.pop_front();
    c.set_t_s(d.time_s());
    c.mutable_synthesized_time()->set_seconds(std::chrono::duration_cast<std::chrono::seconds>(now).count());
    c.mutable_synthesized_time()->set_nanos(static_cast<int>(std::chrono::duration_cast<std::chrono::nanoseconds>(now).count() % 1000000000));
    c.set_superseded(!pending_tones_.empty() && d.style_changes() >= pending_tones_.front().style_changes);
    if (face_ && !c.superseded()) face_->SetTone(c.t_s(), c.tone(), c.tone() == "neutral" ? 0.0 : c.weight());
    ready_tones_.push_back(std::move(c));
  }
}

void LiveStream::OnLegDone(LegId id, const grpc::Status& status) {
  const bool closed = id == kProsody ? prosody_->closing() : id == kInference ? inference_->closing() : control_->closing();
  if (id == kProsody) prosody_ = nullptr;
  if (id == kInference) inference_ = nullptr;
  if (id == kControl) control_ = nullptr;
  if (!error_.ok()) return;
  if (!status.ok()) {
    return Fail(Downstream(kLegNames[id],
                           id == kControl ? RenameField(status, "config.rig_id", "config.models.rig_id") : status));
  }
  if (!closed) {
    return Fail(Refused(grpc::StatusCode::INTERNAL,
                        absl::StrCat(kLegNames[id], ": ended its stream before it was closed")));
  }
  // In order: prosody's last events -> inference's last beliefs -> the
  // planner's last frames.
  if (id == kProsody) {
    face_known_ = true;  // no more speech face: the frames still held go as they are
    if (face_) face_->FinishSpeech();
    FlushFaceFrames();
    // The audio after the last syllable or pause, as unvoiced steps.
    auto v = GapSteps(covered_s_, clock_->audio_s());
    for (auto& f : v) {
      inf::StreamInferRequest q;
      *q.mutable_features() = std::move(f);
      inference_->Send(std::move(q));
    }
    inference_->Close();
  } else if (id == kInference) {
    control_->Close();
  } else {
    MaybeEnd();
  }
}

void LiveStream::StartVisemes() {
  unary_pending_ = true;
  unary_context_ = std::make_unique<grpc::ClientContext>();
  unary_context_->set_deadline(std::min(After(deps_.deadlines->Analysis(clock_->audio_s())), context_->deadline()));
  *analyze_request_.mutable_audio()->mutable_format() = config_.format();
  analyze_request_.mutable_audio()->set_data(std::move(audio_));
  audio_.clear();
  *analyze_request_.mutable_params() = config_.prosody_params();
  analyze_request_.mutable_recognizer()->set_enabled(true);
  analyze_request_.set_request_id(request_id_);
  deps_.prosody->async()->Analyze(unary_context_.get(), &analyze_request_, &analyze_response_,
                                  [self = self_](grpc::Status s) { self->OnAnalyzed(s); });
}

void LiveStream::OnAnalyzed(const grpc::Status& s) {
  std::lock_guard<std::mutex> l(mu_);
  analyze_request_.Clear();
  if (!error_.ok() || !s.ok()) {
    unary_pending_ = false;
    if (!s.ok()) Fail(Downstream("prosody", s));
    Pump();
    return;
  }
  const pr::ProsodyTrack& track = analyze_response_.track();
  *visemes_request_.mutable_phones() = track.phones();
  *visemes_request_.mutable_accents() = track.accents();
  visemes_request_.set_duration_s(track.duration_s());
  *visemes_request_.mutable_params() = config_.viseme_params();
  unary_context_ = std::make_unique<grpc::ClientContext>();
  unary_context_->set_deadline(std::min(After(deps_.deadlines->Analysis(track.duration_s())), context_->deadline()));
  deps_.planner->async()->Visemes(unary_context_.get(), &visemes_request_, &visemes_response_,
                                  [self = self_](grpc::Status st) { self->OnVisemes(st); });
}

void LiveStream::OnVisemes(const grpc::Status& s) {
  std::lock_guard<std::mutex> l(mu_);
  unary_pending_ = false;
  if (!s.ok()) {
    Fail(Downstream("planner", s));
  } else if (error_.ok()) {
    visemes_ready_ = true;
    MaybeEnd();
  }
  Pump();
}

// After the last frames (and the visemes, when asked): visemes, summary, end.
void LiveStream::MaybeEnd() {
  if (ended_ || !error_.ok() || control_ != nullptr || unary_pending_) return;
  if (config_.visemes() && !visemes_ready_) return;
  if (config_.visemes()) {
    v1::StreamAnimateResponse v;
    *v.mutable_visemes() = std::move(*visemes_response_.mutable_track());
    ToClient(std::move(v));
  }
  v1::StreamAnimateResponse r;
  auto* s = r.mutable_summary();
  s->set_audio_s(clock_->audio_s());
  s->set_chunks(clock_->chunks());
  s->set_frames(frames_);
  s->set_syllables(prosody_summary_.syllables());
  s->set_pauses(prosody_summary_.pauses());
  s->set_accents(prosody_summary_.accents());
  s->set_beliefs(beliefs_);
  s->set_decisions(decisions_);
  if (vmc_ != nullptr) {
    const vmc::VmcStats& vs = vmc_->stream().stats();
    s->set_vmc_frames(vs.frames);
    s->set_vmc_packets(vs.packets);
    s->set_vmc_bones(vs.bones);
    s->set_vmc_blendshapes(vs.blendshapes);
  }
  ToClient(std::move(r));
  ended_ = true;
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  log::Info("stream_animated", {{"request_id", request_id_},
                                {"audio_s", clock_->audio_s()},
                                {"frames", frames_},
                                {"beliefs", beliefs_},
                                {"decisions", decisions_},
                                {"wall_s", wall_s}});
}

void LiveStream::ToClient(v1::StreamAnimateResponse r) {
  if (!error_.ok()) return;
  if (vmc_ != nullptr && (r.has_header() || r.has_frames())) {
    // The frames go out to the VMC receiver as they go to the client.
    Status sent = r.has_header() ? vmc_->OnHeader(r.header()) : absl::OkStatus();
    for (int i = 0; sent.ok() && r.has_frames() && i < r.frames().frames_size(); ++i) {
      sent = vmc_->OnFrame(r.frames().frames(i)).status();
    }
    if (!sent.ok()) return Fail(ToGrpcStatus(Annotate(sent, "config.vmc")));
  }
  if (clock_) {
    r.set_last_chunk_sequence(clock_->last_sequence());
    // Media time the frames sent so far reach (the audio clock).
    r.set_audio_time_s(sent_frame_s_ < 0 ? 0.0 : std::min(clock_->audio_s(), sent_frame_s_ + frame_time_s_));
  }
  to_client_.push_back(std::move(r));
}

void LiveStream::Fail(const grpc::Status& s) {
  if (!error_.ok() || finished_) return;
  error_ = s;
  if (prosody_ != nullptr) prosody_->Cancel();
  if (inference_ != nullptr) inference_->Cancel();
  if (control_ != nullptr) control_->Cancel();
  if (unary_pending_) unary_context_->TryCancel();
  // Nothing more for the client but the status.
  while (to_client_.size() > (writing_ ? 1u : 0u)) to_client_.pop_back();
  if (legs_started_ && s.error_code() != grpc::StatusCode::CANCELLED) {
    log::Warn("stream_animate_failed", {{"request_id", request_id_}, {"error", s.error_message()}});
  }
}

void LiveStream::Pump() {
  if (finished_) return;
  if (prosody_ != nullptr) prosody_->Pump();
  if (inference_ != nullptr) inference_->Pump();
  if (control_ != nullptr) control_->Pump();
  if (!writing_ && !to_client_.empty()) {
    writing_ = true;
    StartWrite(&to_client_.front());
  }
  const bool room = to_client_.size() < kMaxQueued &&
                    (prosody_ == nullptr || prosody_->queued() < kMaxQueued) &&
                    (control_ == nullptr || control_->queued() < kMaxQueued);
  if (configured_ && !reading_ && !client_closed_ && error_.ok() && room) {
    reading_ = true;
    StartRead(&in_);
  }
  const bool legs_done = prosody_ == nullptr && inference_ == nullptr && control_ == nullptr;
  if ((ended_ || !error_.ok()) && legs_done && !unary_pending_ && !writing_ && to_client_.empty()) {
    finished_ = true;
    // The slot is free once every leg is over (before the client hears the
    // end, so a client that starts a new stream after it is admitted).
    if (counted_) deps_.streams->fetch_sub(1);
    counted_ = false;
    Finish(error_);
  }
}

}  // namespace

grpc::ServerBidiReactor<v1::StreamAnimateRequest, v1::StreamAnimateResponse>*
CoordinatorServiceImpl::StreamAnimate(grpc::CallbackServerContext* context) {
  const std::uint32_t limit = options_.server().max_message_bytes();
  return LiveStream::Start(context, {&options_, prosody_.get(), inference_.get(), planner_.get(),
                                     &streams_, &deadlines_, watchdog_.get(),
                                     limit > 0 ? limit : std::uint64_t{16} << 20, manager_.get()});
}

}  // namespace kinemo::coordinator
