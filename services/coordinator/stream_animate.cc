// StreamAnimate on the callback API: one server reactor per stream and three
// client reactors for the downstream streams (common/grpc/bidi_leg.h),
// driven by gRPC's callbacks under one mutex per stream (no thread of its
// own). What goes where, the pacing, the face, the tones, VMC and the
// summary are the core's LiveSession (core/live_session.h); this file owns
// the calls, the flow control, the idle timeout and the end.
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
#include <atomic>
#include <chrono>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <type_traits>
#include <utility>

#include <grpcpp/grpcpp.h>

#include "common/grpc/bidi_leg.h"
#include "common/grpc/call_slot.h"
#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "common/server/capacity.h"
#include "services/coordinator/coordinator_service.h"
#include "services/coordinator/core/live_session.h"
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

enum LegId { kProsody = 0, kInference = 1, kControl = 2, kLegs = 3 };
constexpr const char* kLegNames[kLegs] = {"prosody", "inference", "planner"};

grpc::Status Refused(grpc::StatusCode code, const std::string& message) {
  return grpc::Status(code, CapMessage(message, kMaxStatusMessageBytes));
}

std::chrono::system_clock::time_point After(double s) {
  return std::chrono::system_clock::now() + std::chrono::microseconds(static_cast<std::int64_t>(s * 1e6));
}

using ProsodyLeg = ClientBidiLeg<pr::StreamAnalyzeRequest, pr::StreamAnalyzeResponse>;
using InferenceLeg = ClientBidiLeg<inf::StreamInferRequest, inf::StreamInferResponse>;
using ControlLeg = ClientBidiLeg<pl::ControlRequest, pl::ControlResponse>;

// What a stream needs from the service.
struct LiveDeps {
  const v1::CoordinatorOptions* options;
  pr::ProsodyService::Stub* prosody;
  inf::InferenceService::Stub* inference;
  pl::PlannerService::Stub* planner;
  std::atomic<int>* streams;
  const Deadlines* deadlines;  // the visemes' calls (analysis), the legs' idle timeout
  Watchdog* watchdog;
  std::uint64_t max_message_bytes;  // the channels' limit
  SessionManager* sessions;         // config.session_id
};

class LiveStream final : public grpc::ServerBidiReactor<v1::StreamAnimateRequest, v1::StreamAnimateResponse>,
                         public LiveOutput {
 public:
  static LiveStream* Start(grpc::CallbackServerContext* context, const LiveDeps& deps) {
    std::shared_ptr<LiveStream> s(new LiveStream(context, deps));
    s->self_ = s;
    std::lock_guard<std::mutex> l(s->mu_);
    s->reading_ = true;
    s->StartRead(&s->in_);
    return s.get();
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
      } else if (session_ == nullptr && error_.ok()) {
        Configure();
        if (session_ != nullptr && !session_->config().session_id().empty()) subscribe = self_;
      } else if (error_.ok()) {
        Check(session_->OnClientMessage(in_));
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

  // ---- LiveOutput (under mu_) ----
  void ToProsody(pr::StreamAnalyzeRequest r) override { prosody_->Send(std::move(r)); }
  void ToInference(inf::StreamInferRequest r, bool owes) override { inference_->Send(std::move(r), owes); }
  void ToPlanner(pl::ControlRequest r, bool owes) override { control_->Send(std::move(r), owes); }
  void ToClient(v1::StreamAnimateResponse r) override {
    if (error_.ok()) to_client_.push_back(std::move(r));
  }

 private:
  LiveStream(grpc::CallbackServerContext* context, const LiveDeps& deps) : context_(context), deps_(deps) {}

  void Configure();
  template <typename Leg>
  Leg* NewLeg(LegId id);
  void SubscribeSession(const std::shared_ptr<LiveStream>& self);
  void OnSessionEvent(const v1::SessionEvent& e);
  void OnClientHalfClose();
  void OnLegDone(LegId id, const grpc::Status& status, bool closed);
  void StartVisemes();
  void OnAnalyzed(const grpc::Status& s);
  void OnVisemes(const grpc::Status& s);
  void MaybeEnd();
  void Check(const Status& s) {
    if (!s.ok()) Fail(ToGrpcStatus(s));
  }
  void Fail(const grpc::Status& s);
  void Pump();

  grpc::CallbackServerContext* const context_;
  const LiveDeps deps_;
  std::mutex mu_;
  std::shared_ptr<LiveStream> self_;  // until OnDone

  // Server side.
  v1::StreamAnimateRequest in_;
  std::deque<v1::StreamAnimateResponse> to_client_;  // front: being written
  bool reading_ = false, writing_ = false, finished_ = false;
  bool client_closed_ = false, ended_ = false;
  CallSlot slot_;  // animate.max_concurrent_streams
  grpc::Status error_;  // the first error

  std::unique_ptr<LiveSession> session_;  // once configured
  ProsodyLeg* prosody_ = nullptr;         // null once done
  InferenceLeg* inference_ = nullptr;
  ControlLeg* control_ = nullptr;
  bool legs_started_ = false;

  // The session's Vleo (config.session_id).
  std::uint64_t subscription_ = 0;
  bool unsubscribed_ = false;

  // Visemes at the end (prosody.Analyze, then planner.Visemes).
  bool unary_pending_ = false, visemes_ready_ = false;
  std::unique_ptr<grpc::ClientContext> unary_context_;
  pr::AnalyzeRequest analyze_request_;
  pr::AnalyzeResponse analyze_response_;
  pl::VisemesRequest visemes_request_;
  pl::VisemesResponse visemes_response_;
};

void LiveStream::Configure() {
  if (!in_.has_config()) {
    return Fail(Refused(grpc::StatusCode::INVALID_ARGUMENT, "config: must be the first message"));
  }
  const v1::CoordinatorOptions& o = *deps_.options;
  auto session = LiveSession::Create(std::move(*in_.mutable_config()), o,
                                     {deps_.prosody != nullptr, deps_.inference != nullptr, deps_.planner != nullptr},
                                     deps_.max_message_bytes, this);
  if (!session.ok()) return Fail(ToGrpcStatus(session.status()));
  if (!(*session)->config().session_id().empty() && deps_.sessions == nullptr) return Fail(Unavailable("sessions"));
  // The slot is taken last: a stream refused for its config holds none.
  const int max_streams = o.animate().max_concurrent_streams() > 0
                              ? static_cast<int>(o.animate().max_concurrent_streams())
                              : server::DefaultLiveStreamLimit();
  if (!slot_.Take(deps_.streams, max_streams)) {
    return Fail(Refused(grpc::StatusCode::RESOURCE_EXHAUSTED,
                        absl::StrCat("StreamAnimate: ", max_streams,
                                     " streams open (animate.max_concurrent_streams)")));
  }
  session_ = *std::move(session);

  // The three downstream streams, each with its config first.
  prosody_ = NewLeg<ProsodyLeg>(kProsody);
  inference_ = NewLeg<InferenceLeg>(kInference);
  control_ = NewLeg<ControlLeg>(kControl);
  deps_.prosody->async()->StreamAnalyze(prosody_->context(), prosody_);
  deps_.inference->async()->StreamInfer(inference_->context(), inference_);
  deps_.planner->async()->Control(control_->context(), control_);
  session_->Start();
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
}

template <typename Leg>
Leg* LiveStream::NewLeg(LegId id) {
  // The client's deadline and cancellation carry over; a stream lasts at most
  // animate.max_audio_s of audio, so twice that (plus a minute) bounds it.
  auto c = grpc::ClientContext::FromCallbackServerContext(*context_);
  const double max_audio_s =
      deps_.options->animate().max_audio_s() > 0 ? deps_.options->animate().max_audio_s() : 600;
  c->set_deadline(After(2 * max_audio_s + 60));
  typename Leg::Owner owner;
  owner.keep = self_;
  owner.mu = &mu_;
  owner.on_message = [this](auto& r) {
    if (!error_.ok()) return;
    if constexpr (std::is_same_v<Leg, ProsodyLeg>) Check(session_->OnProsody(r));
    if constexpr (std::is_same_v<Leg, InferenceLeg>) session_->OnInference(r);
    if constexpr (std::is_same_v<Leg, ControlLeg>) Check(session_->OnPlanner(r));
  };
  owner.on_done = [this, id](const grpc::Status& status, bool closed) { OnLegDone(id, status, closed); };
  owner.pump = [this] { Pump(); };
  return new Leg(std::move(owner), std::move(c));
}

void LiveStream::OnClientHalfClose() {
  client_closed_ = true;
  if (session_ == nullptr || !error_.ok()) {
    ended_ = true;  // closed before its config: nothing to do
    return;
  }
  prosody_->Close();
  if (session_->config().visemes()) StartVisemes();
}

void LiveStream::SubscribeSession(const std::shared_ptr<LiveStream>& self) {
  // session_ is not replaced after Configure.
  auto id = deps_.sessions->Subscribe(session_->config().session_id(),
                                      [weak = std::weak_ptr<LiveStream>(self)](const v1::SessionEvent& e) {
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
  if (!e.has_snapshot() && !e.has_action_changed()) return;
  session_->OnSessionEvent(e);
  Pump();
}

void LiveStream::OnLegDone(LegId id, const grpc::Status& status, bool closed) {
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
    Check(session_->OnProsodyEnd());
    if (inference_ != nullptr) inference_->Close();
  } else if (id == kInference) {
    control_->Close();
  } else {
    MaybeEnd();
  }
}

void LiveStream::StartVisemes() {
  unary_pending_ = true;
  unary_context_ = std::make_unique<grpc::ClientContext>();
  unary_context_->set_deadline(
      std::min(After(deps_.deadlines->Analysis(session_->audio_s())), context_->deadline()));
  analyze_request_ = session_->TakeVisemesAnalysis();
  deps_.prosody->async()->Analyze(unary_context_.get(), &analyze_request_, &analyze_response_,
                                  [self = self_](grpc::Status s) { self->OnAnalyzed(s); });
}

void LiveStream::OnAnalyzed(const grpc::Status& s) {
  std::lock_guard<std::mutex> l(mu_);
  analyze_request_.Clear();
  if (!error_.ok() || !s.ok()) {
    unary_pending_ = false;
    unary_context_.reset();  // nothing of the call outlives the stream's end
    if (!s.ok()) Fail(Downstream("prosody", s));
    Pump();
    return;
  }
  const pr::ProsodyTrack& track = analyze_response_.track();
  visemes_request_ = session_->VisemesRequestFor(track);
  unary_context_ = std::make_unique<grpc::ClientContext>();
  unary_context_->set_deadline(std::min(After(deps_.deadlines->Analysis(track.duration_s())), context_->deadline()));
  deps_.planner->async()->Visemes(unary_context_.get(), &visemes_request_, &visemes_response_,
                                  [self = self_](grpc::Status st) { self->OnVisemes(st); });
}

void LiveStream::OnVisemes(const grpc::Status& s) {
  std::lock_guard<std::mutex> l(mu_);
  unary_pending_ = false;
  unary_context_.reset();  // nothing of the call outlives the stream's end
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
  const bool visemes = session_->config().visemes();
  if (visemes && !visemes_ready_) return;
  const Status end = session_->End(visemes ? visemes_response_.mutable_track() : nullptr);
  if (!end.ok()) return Check(end);
  ended_ = true;
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
    log::Warn("stream_animate_failed", {{"request_id", session_->request_id()}, {"error", s.error_message()}});
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
  const bool room = to_client_.size() < kMaxQueued && (prosody_ == nullptr || prosody_->queued() < kMaxQueued) &&
                    (control_ == nullptr || control_->queued() < kMaxQueued);
  if (session_ != nullptr && !reading_ && !client_closed_ && error_.ok() && room) {
    reading_ = true;
    StartRead(&in_);
  }
  const bool legs_done = prosody_ == nullptr && inference_ == nullptr && control_ == nullptr;
  if ((ended_ || !error_.ok()) && legs_done && !unary_pending_ && !writing_ && to_client_.empty()) {
    finished_ = true;
    // The slot is free once every leg is over (before the client hears the
    // end, so a client that starts a new stream after it is admitted).
    slot_.Release();
    Finish(error_);
  }
}

}  // namespace

grpc::ServerBidiReactor<v1::StreamAnimateRequest, v1::StreamAnimateResponse>*
CoordinatorServiceImpl::StreamAnimate(grpc::CallbackServerContext* context) {
  const std::uint32_t limit = options_.server().max_message_bytes();
  return LiveStream::Start(context, {&options_, prosody_.get(), inference_.get(), planner_.get(), &streams_,
                                     &deadlines_, watchdog_.get(), limit > 0 ? limit : std::uint64_t{16} << 20,
                                     manager_.get()});
}

}  // namespace kinemo::coordinator
