// The studio's bridge to the coordinator (bridge.h).
#include "services/studio/bridge.h"

#include <google/protobuf/text_format.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>
#include <vector>

#include "common/grpc/status_mapping.h"
#include "common/grpc/tls_credentials.h"
#include "common/logging/log.h"
#include "common/metrics/metrics.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "services/studio/core/character.h"
#include "services/studio/core/cube_videos.h"
#include "services/studio/core/messages.h"

#ifndef KINEMO_VERSION
#define KINEMO_VERSION "dev"
#endif

namespace kinemo::studio {

namespace cv1 = kinemo::coordinator::v1;
namespace pv1 = kinemo::prosody::v1;

// Live streams and watches have no natural end; their deadlines only bound
// a call the page forgot.
constexpr double kStreamDeadlineS = 3600;
constexpr double kWatchDeadlineS = 24 * 3600;
// Stream messages waiting for the previous write (20 ms chunks: 5 s).
constexpr std::size_t kMaxPendingWrites = 250;

namespace {
class CallSet;
}

struct CoordinatorBridge::Shared {
  v1::StudioOptions options;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<cv1::CoordinatorService::Stub> coordinator;
  std::unique_ptr<pv1::ProsodyService::Stub> prosody;
  std::unique_ptr<CharacterLibrary> characters;
  std::unique_ptr<CubeVideos> cubes;
  kinemo::cube_tracker::v1::CubeModel cube_model;  // the studio's cube (cube_data_dir/vleo.cube)
  bool has_cube_model = false;

  std::mutex mu;
  std::condition_variable cv;
  int running = 0;                            // guarded by mu
  std::vector<std::weak_ptr<CallSet>> sets;   // guarded by mu
  bool shutting_down = false;                 // guarded by mu
};

namespace {

using Shared = CoordinatorBridge::Shared;

std::chrono::system_clock::time_point Deadline(double seconds) {
  return std::chrono::system_clock::now() + std::chrono::microseconds(static_cast<std::int64_t>(seconds * 1e6));
}

// "audio.data: bad" from the coordinator becomes "animate.audio.data: bad":
// errors name the field as the page's message spells it.
std::string PrefixField(const std::string& call, const std::string& message) {
  const std::size_t colon = message.find(": ");
  if (colon != std::string::npos && colon > 0) {
    bool path = true;
    for (std::size_t i = 0; i < colon && path; ++i) {
      const char c = message[i];
      path = (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '.' || c == '[' || c == ']';
    }
    if (path) return call + "." + message;
  }
  return call + ": " + message;
}

class Call;

// The calls of one socket, by id.
class CallSet {
 public:
  // False (and no change) if the socket closed.
  bool Add(std::uint32_t id, std::shared_ptr<Call> call) {
    std::lock_guard<std::mutex> l(mu_);
    if (closed_) return false;
    calls_[id] = std::move(call);
    return true;
  }
  std::shared_ptr<Call> Find(std::uint32_t id) {
    std::lock_guard<std::mutex> l(mu_);
    auto it = calls_.find(id);
    return it == calls_.end() ? nullptr : it->second;
  }
  std::size_t size() {
    std::lock_guard<std::mutex> l(mu_);
    return calls_.size();
  }
  void Remove(std::uint32_t id, const Call* call) {
    std::lock_guard<std::mutex> l(mu_);
    auto it = calls_.find(id);
    if (it != calls_.end() && it->second.get() == call) calls_.erase(it);
  }
  // Marks the set closed and returns its calls (to cancel outside the lock).
  std::vector<std::shared_ptr<Call>> Close() {
    std::lock_guard<std::mutex> l(mu_);
    closed_ = true;
    std::vector<std::shared_ptr<Call>> out;
    for (auto& [id, call] : calls_) out.push_back(call);
    return out;
  }

 private:
  std::mutex mu_;
  std::map<std::uint32_t, std::shared_ptr<Call>> calls_;
  bool closed_ = false;
};

// The character a socket chose (`character`); its streams' frames are
// retargeted onto it.
class SocketCharacter {
 public:
  std::shared_ptr<const Character> Get() {
    std::lock_guard<std::mutex> l(mu_);
    return current_;
  }
  void Set(std::shared_ptr<const Character> c) {
    std::lock_guard<std::mutex> l(mu_);
    current_ = std::move(c);
  }

 private:
  std::mutex mu_;
  std::shared_ptr<const Character> current_;
};

// The cube video a socket uploaded and attached: removed when the socket
// attaches another, detaches that session or closes.
class SocketCube {
 public:
  explicit SocketCube(CubeVideos* videos) : videos_(videos) {}
  void Set(std::string session_id, CubeVideo video) {
    std::lock_guard<std::mutex> l(mu_);
    videos_->Remove(video_);
    session_id_ = std::move(session_id);
    video_ = std::move(video);
  }
  void Drop(const std::string& session_id) {
    std::lock_guard<std::mutex> l(mu_);
    if (session_id != session_id_) return;
    videos_->Remove(video_);
    video_ = CubeVideo{};
  }
  void DropAll() {
    std::lock_guard<std::mutex> l(mu_);
    videos_->Remove(video_);
    video_ = CubeVideo{};
  }

 private:
  CubeVideos* videos_;  // Shared's, which outlives the socket
  std::mutex mu_;
  std::string session_id_;
  CubeVideo video_;
};

struct Env {
  std::shared_ptr<Shared> shared;
  std::shared_ptr<CallSet> set;
  std::shared_ptr<SocketConnection> connection;
  std::shared_ptr<SocketCharacter> character;
  std::shared_ptr<SocketCube> cube;
};

// One running call of a socket. Counted in Shared::running from
// construction to destruction.
class Call {
 public:
  Call(Env env, std::uint32_t id, std::string name) : env_(std::move(env)), id_(id), name_(std::move(name)) {
    std::lock_guard<std::mutex> l(env_.shared->mu);
    ++env_.shared->running;
  }
  virtual ~Call() {
    std::lock_guard<std::mutex> l(env_.shared->mu);
    --env_.shared->running;
    env_.shared->cv.notify_all();
  }
  virtual void Cancel() = 0;

 protected:
  void SendMessage(v1::ServerMessage& message) {
    message.set_id(id_);
    env_.connection->Send(EncodeServerMessage(message));
  }
  // The call is over: an error frame, or `ended` for streams and watches.
  void Finish(const grpc::Status& status, bool send_ended) {
    if (!status.ok()) {
      const Status s = FromGrpcStatus(status);
      env_.connection->Send(EncodeError(id_, Status(s.code(), PrefixField(name_, std::string(s.message())))));
    } else if (send_ended) {
      v1::ServerMessage m;
      m.mutable_ended();
      SendMessage(m);
    }
    env_.set->Remove(id_, this);
  }

  Env env_;
  const std::uint32_t id_;
  const std::string name_;
};

// A unary call; its answer goes in the ServerMessage field of the call's name.
template <class Request, class Response>
class UnaryCall : public Call, public std::enable_shared_from_this<UnaryCall<Request, Response>> {
 public:
  using Invoke = std::function<void(grpc::ClientContext*, const Request*, Response*, std::function<void(grpc::Status)>)>;
  UnaryCall(Env env, std::uint32_t id, std::string name, Request request)
      : Call(std::move(env), id, std::move(name)), request_(std::move(request)) {}

  void Start(double deadline_s, const Invoke& invoke) {
    context_.set_deadline(Deadline(deadline_s));
    invoke(&context_, &request_, &response_, [self = this->shared_from_this()](grpc::Status status) {
      if (status.ok()) {
        v1::ServerMessage m;
        const auto* field = v1::ServerMessage::descriptor()->FindFieldByName(self->name_);
        google::protobuf::Message* target = m.GetReflection()->MutableMessage(&m, field);
        target->GetReflection()->Swap(target, &self->response_);
        self->SendMessage(m);
      }
      self->Finish(status, false);
    });
  }
  void Cancel() override { context_.TryCancel(); }

 private:
  grpc::ClientContext context_;
  Request request_;
  Response response_;
};

// CoordinatorService.StreamAnimate: the page's messages are written in
// order (one write at a time, the rest queued); every response is sent on.
// The socket's thread starts writes from outside the reactions, so a hold
// keeps the call from finishing until the page ends or cancels it, or the
// server ends it.
class StreamCall : public Call,
                   public grpc::ClientBidiReactor<cv1::StreamAnimateRequest, cv1::StreamAnimateResponse> {
 public:
  // While it runs, the studio's AR drawing waits (CubeVideos).
  StreamCall(Env env, std::uint32_t id) : Call(std::move(env), id, "stream") {
    env_.shared->cubes->LiveStreamStarted();
  }
  ~StreamCall() override { env_.shared->cubes->LiveStreamEnded(); }

  // `self` is this call; it lives until OnDone.
  void Start(std::shared_ptr<StreamCall> self, cv1::StreamAnimateRequest first) {
    self_ = std::move(self);
    context_.set_deadline(Deadline(kStreamDeadlineS));
    env_.shared->coordinator->async()->StreamAnimate(&context_, this);
    AddHold();
    (void)Write(std::move(first));
    StartRead(&response_);
    StartCall();
  }

  Status Write(cv1::StreamAnimateRequest request) {
    std::lock_guard<std::recursive_mutex> l(mu_);
    if (released_ || ending_) {
      return absl::FailedPreconditionError(kinemo::StrCat("stream: stream ", id_, " has ended"));
    }
    if (pending_.size() >= kMaxPendingWrites) {
      return absl::ResourceExhaustedError(kinemo::StrCat(
          "stream: ", pending_.size(), " messages already wait to be sent to the coordinator"));
    }
    pending_.push_back(std::move(request));
    if (!writing_) {
      writing_ = true;
      StartWrite(&pending_.front());
    }
    return absl::OkStatus();
  }

  Status End() {
    std::lock_guard<std::recursive_mutex> l(mu_);
    if (released_ || ending_) {
      return absl::FailedPreconditionError(kinemo::StrCat("stream_end: stream ", id_, " has ended"));
    }
    ending_ = true;
    if (!writing_) FinishWrites();
    return absl::OkStatus();
  }

  void Cancel() override {
    context_.TryCancel();
    std::lock_guard<std::recursive_mutex> l(mu_);
    Release();
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::recursive_mutex> l(mu_);
    pending_.pop_front();
    if (!ok) {  // the call is over; its status tells why
      writing_ = false;
      pending_.clear();
      Release();
      return;
    }
    if (!pending_.empty()) {
      StartWrite(&pending_.front());
    } else {
      writing_ = false;
      if (ending_) FinishWrites();
    }
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      std::lock_guard<std::recursive_mutex> l(mu_);
      Release();
      return;
    }
    v1::ServerMessage m;
    m.mutable_stream()->Swap(&response_);
    SendMessage(m);
    DriveCharacter(m.stream());
    StartRead(&response_);
  }

  void OnDone(const grpc::Status& status) override {
    Finish(status, true);
    std::shared_ptr<StreamCall> last = std::move(self_);  // may be the last reference
  }

 private:
  // The stream's frames on the socket's character, sent right after them.
  // A skeleton the character cannot follow is logged once and the stream
  // goes on without it.
  void DriveCharacter(const cv1::StreamAnimateResponse& response) {
    if (character_failed_) return;
    Status s = absl::OkStatus();
    if (response.has_header()) {
      s = live_.SetHeader(response.header());
    } else if (response.has_frames()) {
      auto motion = live_.Drive(env_.character->Get(), response.frames());
      if (!motion.ok()) {
        s = motion.status();
      } else if (*motion) {
        v1::ServerMessage m;
        m.set_allocated_character_motion(motion->release());
        SendMessage(m);
      }
    }
    if (!s.ok()) {
      character_failed_ = true;
      log::Warn("stream_character_failed", {{"error", std::string(s.message())}});
    }
  }

  // Under mu_.
  void FinishWrites() {
    StartWritesDone();
    Release();
  }
  void Release() {
    if (released_) return;
    released_ = true;
    RemoveHold();
  }

  grpc::ClientContext context_;
  cv1::StreamAnimateResponse response_;
  std::recursive_mutex mu_;  // a reaction may run inline in StartWrite
  std::deque<cv1::StreamAnimateRequest> pending_;
  bool writing_ = false, ending_ = false, released_ = false;
  std::shared_ptr<StreamCall> self_;
  LiveCharacter live_;              // reads only (one at a time)
  bool character_failed_ = false;
};

// CoordinatorService.WatchSession: every event is sent on.
class WatchCall : public Call, public grpc::ClientReadReactor<cv1::SessionEvent> {
 public:
  WatchCall(Env env, std::uint32_t id, cv1::WatchSessionRequest request)
      : Call(std::move(env), id, "watch_session"), request_(std::move(request)) {}

  void Start(std::shared_ptr<WatchCall> self) {
    self_ = std::move(self);
    context_.set_deadline(Deadline(kWatchDeadlineS));
    env_.shared->coordinator->async()->WatchSession(&context_, &request_, this);
    StartRead(&event_);
    StartCall();
  }
  void Cancel() override { context_.TryCancel(); }
  void OnReadDone(bool ok) override {
    if (!ok) return;
    v1::ServerMessage m;
    m.mutable_session_event()->Swap(&event_);
    SendMessage(m);
    StartRead(&event_);
  }
  void OnDone(const grpc::Status& status) override {
    // A watch the page cancelled ends quietly.
    Finish(status.error_code() == grpc::StatusCode::CANCELLED ? grpc::Status::OK : status, true);
    std::shared_ptr<WatchCall> last = std::move(self_);
  }

 private:
  grpc::ClientContext context_;
  cv1::WatchSessionRequest request_;
  cv1::SessionEvent event_;
  std::shared_ptr<WatchCall> self_;
};

// attach_cube: the video is made ready off the socket's thread (a bundled
// scenario is rendered on its first use, an upload written and opened), then
// CoordinatorService.AttachCube plays it in real time with the studio's
// cube. A refused upload is removed at once.
class AttachCubeCall : public Call, public std::enable_shared_from_this<AttachCubeCall> {
 public:
  AttachCubeCall(Env env, std::uint32_t id, v1::AttachCubeVideo request)
      : Call(std::move(env), id, "attach_cube"), request_(std::move(request)) {}

  void Start(double deadline_s) {
    std::thread([self = shared_from_this(), deadline_s] { self->Run(deadline_s); }).detach();
  }
  void Cancel() override {
    cancelled_ = true;
    context_.TryCancel();
  }

 private:
  void Run(double deadline_s) {
    auto video = env_.shared->cubes->Prepare(request_);
    if (!video.ok() || cancelled_) {
      if (video.ok()) env_.shared->cubes->Remove(*video);
      env_.connection->Send(EncodeError(id_, video.ok() ? absl::CancelledError("attach_cube: cancelled")
                                                        : video.status()));
      env_.set->Remove(id_, this);
      return;
    }
    video_ = *std::move(video);
    env_.shared->cubes->SetArCharacter(&video_, env_.character->Get());
    attach_.set_session_id(request_.session_id());
    attach_.mutable_source()->set_video_file(video_.video);
    attach_.mutable_source()->set_realtime(true);
    if (!video_.camera.empty()) attach_.mutable_config()->set_intrinsics_file(video_.camera);
    if (env_.shared->has_cube_model) *attach_.mutable_config()->mutable_cube_model() = env_.shared->cube_model;
    context_.set_deadline(Deadline(deadline_s));
    env_.shared->coordinator->async()->AttachCube(&context_, &attach_, &response_,
                                                  [self = shared_from_this()](grpc::Status s) { self->Done(s); });
  }

  void Done(const grpc::Status& status) {
    if (status.ok()) {
      if (video_.uploaded || video_.own_ar) env_.cube->Set(request_.session_id(), video_);
      v1::ServerMessage m;
      m.mutable_attach_cube()->Swap(&response_);
      SendMessage(m);
      // Then its AR view, with the same id: at once if drawn before, else
      // when the studio's AR worker has drawn it.
      env_.shared->cubes->RenderAr(
          video_, [connection = env_.connection, id = id_, session = request_.session_id()](
                      StatusOr<CubeArResult> drawn) { SendCubeAr(*connection, id, session, drawn); });
    } else {
      env_.shared->cubes->Remove(video_);
    }
    Finish(status, false);
  }

  static void SendCubeAr(SocketConnection& connection, std::uint32_t id, const std::string& session_id,
                         const StatusOr<CubeArResult>& drawn) {
    if (drawn.status().code() == absl::StatusCode::kCancelled) return;  // removed, or the studio stops
    v1::ServerMessage m;
    m.set_id(id);
    v1::CubeArVideo* ar = m.mutable_cube_ar_video();
    ar->set_session_id(session_id);
    if (drawn.ok()) {
      ar->set_url(drawn->url);
      ar->set_frames(static_cast<std::uint32_t>(drawn->frames));
      ar->set_drawn_frames(static_cast<std::uint32_t>(drawn->drawn));
      ar->set_width(static_cast<std::uint32_t>(drawn->width));
      ar->set_height(static_cast<std::uint32_t>(drawn->height));
      ar->set_fps(drawn->fps);
      ar->set_render_s(drawn->render_s);
    } else {
      ar->set_error(std::string(drawn.status().message()));
    }
    connection.Send(EncodeServerMessage(m));
  }

  v1::AttachCubeVideo request_;
  std::atomic<bool> cancelled_{false};
  CubeVideo video_;
  grpc::ClientContext context_;
  cv1::AttachCubeRequest attach_;
  cv1::AttachCubeResponse response_;
};

// One socket: decodes the page's messages and starts or continues calls.
// The studio's metrics (GET /metrics on its HTTP port, common/metrics).
struct StudioSocketMetrics {
  prometheus::Counter& opened = metrics::Counter("kinemo_studio_sockets_opened_total", "WebSockets opened by pages");
  prometheus::Gauge& open = metrics::Gauge("kinemo_studio_sockets_open", "WebSockets open now");
  prometheus::Counter& messages =
      metrics::Counter("kinemo_studio_messages_total", "socket messages decoded and dispatched to the coordinator");
  prometheus::Counter& refused =
      metrics::Counter("kinemo_studio_messages_refused_total", "socket messages answered with an error frame");
};
StudioSocketMetrics& SocketMetrics() {
  static StudioSocketMetrics m;
  return m;
}

class SocketBridge : public SocketHandler {
 public:
  SocketBridge(std::shared_ptr<Shared> shared, std::shared_ptr<SocketConnection> connection)
      : env_{std::move(shared), std::make_shared<CallSet>(), std::move(connection),
             std::make_shared<SocketCharacter>(), nullptr} {
    env_.cube = std::make_shared<SocketCube>(env_.shared->cubes.get());
    {
      std::lock_guard<std::mutex> l(env_.shared->mu);
      std::erase_if(env_.shared->sets, [](const std::weak_ptr<CallSet>& s) { return s.expired(); });
      env_.shared->sets.push_back(env_.set);
    }
    v1::ServerMessage hello;
    hello.mutable_hello()->set_version(KINEMO_VERSION);
    hello.mutable_hello()->set_max_upload_bytes(env_.shared->options.max_upload_bytes());
    hello.mutable_hello()->set_coordinator(env_.shared->options.coordinator().address());
    hello.mutable_hello()->set_max_character_bytes(env_.shared->options.max_character_bytes());
    if (env_.shared->cubes->enabled()) {
      hello.mutable_hello()->set_max_cube_video_bytes(env_.shared->options.max_cube_video_bytes());
      for (const auto& name : env_.shared->cubes->scenarios()) hello.mutable_hello()->add_cube_scenarios(name);
    }
    env_.connection->Send(EncodeServerMessage(hello));
    SocketMetrics().opened.Increment();
    SocketMetrics().open.Increment();
  }

  void OnText(std::string_view text) override {
    std::uint32_t id = 0;
    auto message = DecodeClientMessage(text, &id);
    if (!message.ok()) {
      SocketMetrics().refused.Increment();
      return Fail(id, message.status());
    }
    SocketMetrics().messages.Increment();
    if (Status s = Dispatch(*std::move(message)); !s.ok()) {
      SocketMetrics().refused.Increment();
      Fail(id, s);
    }
  }

  void OnClose() override {
    SocketMetrics().open.Decrement();
    for (const auto& call : env_.set->Close()) call->Cancel();
    env_.cube->DropAll();
  }

 private:
  void Fail(std::uint32_t id, const Status& status) { env_.connection->Send(EncodeError(id, status)); }

  Status CheckNew(std::uint32_t id, const std::string& name) {
    if (env_.set->Find(id) != nullptr) {
      return InvalidField("id", "call ", id, " is still running; give each running call its own id");
    }
    if (env_.set->size() >= env_.shared->options.max_calls_per_connection()) {
      return absl::ResourceExhaustedError(kinemo::StrCat(name, ": ", env_.set->size(),
                                                         " calls are running on this socket (at most ",
                                                         env_.shared->options.max_calls_per_connection(), ")"));
    }
    return absl::OkStatus();
  }

  template <class Request, class Response>
  Status Unary(std::uint32_t id, const std::string& name, Request request, double deadline_s,
               const typename UnaryCall<Request, Response>::Invoke& invoke) {
    KINEMO_RETURN_IF_ERROR(CheckNew(id, name));
    auto call = std::make_shared<UnaryCall<Request, Response>>(env_, id, name, std::move(request));
    if (!env_.set->Add(id, call)) return absl::OkStatus();  // the socket closed
    call->Start(deadline_s, invoke);
    return absl::OkStatus();
  }

  Status Dispatch(v1::ClientMessage m) {
    const std::uint32_t id = m.id();
    const double session_s = env_.shared->options.coordinator().deadline_s();
    const double animate_s = env_.shared->options.animate_deadline_s();
    auto* coordinator = env_.shared->coordinator.get();
    auto* prosody = env_.shared->prosody.get();
    switch (m.call_case()) {
      case v1::ClientMessage::kAnimate:
        return Unary<cv1::AnimateRequest, cv1::AnimateResponse>(
            id, "animate", std::move(*m.mutable_animate()), animate_s,
            [coordinator](auto* c, auto* q, auto* r, auto done) { coordinator->async()->Animate(c, q, r, done); });
      case v1::ClientMessage::kAnalyze:
        return Unary<pv1::AnalyzeRequest, pv1::AnalyzeResponse>(
            id, "analyze", std::move(*m.mutable_analyze()), animate_s,
            [prosody](auto* c, auto* q, auto* r, auto done) { prosody->async()->Analyze(c, q, r, done); });
      case v1::ClientMessage::kOpenSession:
        return Unary<cv1::OpenSessionRequest, cv1::OpenSessionResponse>(
            id, "open_session", std::move(*m.mutable_open_session()), session_s,
            [coordinator](auto* c, auto* q, auto* r, auto done) { coordinator->async()->OpenSession(c, q, r, done); });
      case v1::ClientMessage::kCloseSession:
        return Unary<cv1::CloseSessionRequest, cv1::CloseSessionResponse>(
            id, "close_session", std::move(*m.mutable_close_session()), session_s,
            [coordinator](auto* c, auto* q, auto* r, auto done) { coordinator->async()->CloseSession(c, q, r, done); });
      case v1::ClientMessage::kListSessions:
        return Unary<cv1::ListSessionsRequest, cv1::ListSessionsResponse>(
            id, "list_sessions", std::move(*m.mutable_list_sessions()), session_s,
            [coordinator](auto* c, auto* q, auto* r, auto done) { coordinator->async()->ListSessions(c, q, r, done); });
      case v1::ClientMessage::kGetSession:
        return Unary<cv1::GetSessionRequest, cv1::Session>(
            id, "get_session", std::move(*m.mutable_get_session()), session_s,
            [coordinator](auto* c, auto* q, auto* r, auto done) { coordinator->async()->GetSession(c, q, r, done); });
      case v1::ClientMessage::kAct:
        return Unary<cv1::ActRequest, cv1::ActResponse>(
            id, "act", std::move(*m.mutable_act()), session_s,
            [coordinator](auto* c, auto* q, auto* r, auto done) { coordinator->async()->Act(c, q, r, done); });
      case v1::ClientMessage::kWatchSession: {
        KINEMO_RETURN_IF_ERROR(CheckNew(id, "watch_session"));
        auto call = std::make_shared<WatchCall>(env_, id, std::move(*m.mutable_watch_session()));
        if (env_.set->Add(id, call)) call->Start(call);
        return absl::OkStatus();
      }
      case v1::ClientMessage::kStream: {
        if (auto running = env_.set->Find(id)) {
          auto* stream = dynamic_cast<StreamCall*>(running.get());
          if (stream == nullptr) return InvalidField("id", "call ", id, " is not a stream");
          return stream->Write(std::move(*m.mutable_stream()));
        }
        if (!m.stream().has_config()) {
          return InvalidField("stream", "no stream ", id, " is running; a stream's first message is stream.config");
        }
        KINEMO_RETURN_IF_ERROR(CheckNew(id, "stream"));
        auto call = std::make_shared<StreamCall>(env_, id);
        if (env_.set->Add(id, call)) call->Start(call, std::move(*m.mutable_stream()));
        return absl::OkStatus();
      }
      case v1::ClientMessage::kStreamEnd: {
        auto running = env_.set->Find(id);
        auto* stream = dynamic_cast<StreamCall*>(running.get());
        if (stream == nullptr) return InvalidField("stream_end", "no stream ", id, " is running");
        return stream->End();
      }
      case v1::ClientMessage::kCancel:
        if (auto running = env_.set->Find(id)) running->Cancel();
        return absl::OkStatus();
      case v1::ClientMessage::kCharacter: {
        KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<const Character> c,
                                env_.shared->characters->Select(m.character()));
        env_.character->Set(c);
        v1::ServerMessage answer;
        answer.set_id(id);
        *answer.mutable_character() = c->info;
        env_.connection->Send(EncodeServerMessage(answer));
        return absl::OkStatus();
      }
      case v1::ClientMessage::kRetarget: {
        std::shared_ptr<const Character> c = env_.character->Get();
        if (!c) return absl::FailedPreconditionError("retarget: choose a character first (send `character`)");
        KINEMO_ASSIGN_OR_RETURN(v1::CharacterMotion motion, RetargetBvh(c, m.retarget().bvh(), m.retarget().name(),
                                                                          m.retarget().has_face() ? &m.retarget().face() : nullptr));
        v1::ServerMessage answer;
        answer.set_id(id);
        answer.mutable_character_motion()->Swap(&motion);
        env_.connection->Send(EncodeServerMessage(answer));
        return absl::OkStatus();
      }
      case v1::ClientMessage::kExportMotion: {
        std::shared_ptr<const Character> c = env_.character->Get();
        if (!c) return absl::FailedPreconditionError("export_motion: choose a character first (send `character`)");
        KINEMO_ASSIGN_OR_RETURN(v1::ExportedFile file, ExportBvh(c, m.export_motion()));
        v1::ServerMessage answer;
        answer.set_id(id);
        answer.mutable_exported_file()->Swap(&file);
        env_.connection->Send(EncodeServerMessage(answer));
        return absl::OkStatus();
      }
      case v1::ClientMessage::kAttachCube: {
        KINEMO_RETURN_IF_ERROR(CheckNew(id, "attach_cube"));
        auto call = std::make_shared<AttachCubeCall>(env_, id, std::move(*m.mutable_attach_cube()));
        if (env_.set->Add(id, call)) call->Start(session_s);
        return absl::OkStatus();
      }
      case v1::ClientMessage::kDetachCube:
        env_.cube->Drop(m.detach_cube().session_id());
        return Unary<cv1::DetachCubeRequest, cv1::DetachCubeResponse>(
            id, "detach_cube", std::move(*m.mutable_detach_cube()), session_s,
            [coordinator](auto* c, auto* q, auto* r, auto done) { coordinator->async()->DetachCube(c, q, r, done); });
      case v1::ClientMessage::CALL_NOT_SET:
        break;
    }
    return InvalidField("message", "names no call");
  }

  Env env_;
};

}  // namespace

CoordinatorBridge::CoordinatorBridge(std::shared_ptr<Shared> shared) : shared_(std::move(shared)) {}

CoordinatorBridge::~CoordinatorBridge() { Shutdown(5); }

StatusOr<std::shared_ptr<CoordinatorBridge>> CoordinatorBridge::Create(const v1::StudioOptions& options) {
  auto shared = std::make_shared<Shared>();
  shared->options = options;
  const auto& endpoint = options.coordinator();
  KINEMO_ASSIGN_OR_RETURN(auto credentials,
                          MakeChannelCredentials(ClientTlsFilesAt("coordinator", endpoint.ca_file(),
                                                                  endpoint.cert_file(), endpoint.key_file())));
  grpc::ChannelArguments args;
  // Answers carry whole BVH files and viseme tracks; requests whole WAVs.
  args.SetMaxReceiveMessageSize(512 << 20);
  args.SetMaxSendMessageSize(static_cast<int>(std::min<std::uint64_t>(options.max_upload_bytes(), 512u << 20)));
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, static_cast<int>(endpoint.max_reconnect_backoff_s() * 1000));
  shared->channel = grpc::CreateCustomChannel(endpoint.address(), credentials, args);
  shared->coordinator = cv1::CoordinatorService::NewStub(shared->channel);
  shared->prosody = pv1::ProsodyService::NewStub(shared->channel);
  shared->characters = std::make_unique<CharacterLibrary>(options);
  shared->cubes = std::make_unique<CubeVideos>(options);
  if (shared->cubes->enabled()) {
    if (!google::protobuf::TextFormat::ParseFromString(shared->cubes->cube_model_text(), &shared->cube_model) ||
        shared->cubes->cube_model_text().empty()) {
      return InvalidField("cube_data_dir", "\"", options.cube_data_dir(), "\" has no readable vleo.cube");
    }
    shared->has_cube_model = true;
  }
  return std::shared_ptr<CoordinatorBridge>(new CoordinatorBridge(std::move(shared)));
}

std::unique_ptr<SocketHandler> CoordinatorBridge::NewHandler(std::shared_ptr<SocketConnection> connection) {
  return std::make_unique<SocketBridge>(shared_, std::move(connection));
}

std::string CoordinatorBridge::HealthJson() const {
  const char* state = "UNKNOWN";
  switch (shared_->channel->GetState(/*try_to_connect=*/true)) {
    case GRPC_CHANNEL_IDLE: state = "IDLE"; break;
    case GRPC_CHANNEL_CONNECTING: state = "CONNECTING"; break;
    case GRPC_CHANNEL_READY: state = "READY"; break;
    case GRPC_CHANNEL_TRANSIENT_FAILURE: state = "TRANSIENT_FAILURE"; break;
    case GRPC_CHANNEL_SHUTDOWN: state = "SHUTDOWN"; break;
  }
  return nlohmann::json{{"status", "SERVING"},
                        {"coordinator", shared_->options.coordinator().address()},
                        {"coordinator_state", state}}
      .dump();
}

int CoordinatorBridge::calls_running() const {
  std::lock_guard<std::mutex> l(shared_->mu);
  return shared_->running;
}

void CoordinatorBridge::Shutdown(double grace_s) {
  shared_->cubes->Shutdown();  // an AR video being drawn stops at its next frame
  std::vector<std::shared_ptr<CallSet>> sets;
  {
    std::lock_guard<std::mutex> l(shared_->mu);
    shared_->shutting_down = true;
    for (const auto& w : shared_->sets) {
      if (auto s = w.lock()) sets.push_back(std::move(s));
    }
  }
  for (const auto& set : sets) {
    for (const auto& call : set->Close()) call->Cancel();
  }
  std::unique_lock<std::mutex> l(shared_->mu);
  if (!shared_->cv.wait_for(l, std::chrono::duration<double>(grace_s), [this] { return shared_->running == 0; })) {
    log::Warn("calls_still_running", {{"calls", shared_->running}});
  }
}

}  // namespace kinemo::studio
