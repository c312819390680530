#include "services/coordinator/coordinator_service.h"

#include <algorithm>
#include <chrono>
#include <deque>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include "common/grpc/status_mapping.h"
#include "common/grpc/tls_credentials.h"
#include "common/logging/log.h"
#include "common/server/service_host.h"
#include "services/coordinator/core/animate_plan.h"
#include "services/coordinator/core/animate_requests.h"
#include "services/coordinator/core/sqlite_session_store.h"
#include "services/coordinator/downstream.h"
#include "services/coordinator/idle_watchdog.h"
#include "services/coordinator/robot_relay.h"

namespace kinemo::coordinator {

namespace ct = ::kinemo::cube_tracker::v1;
namespace inf = ::kinemo::inference::v1;
namespace pl = ::kinemo::planner::v1;
namespace pr = ::kinemo::prosody::v1;

namespace {

double EndpointBackoff(const v1::ServiceEndpoint& e) {
  return e.max_reconnect_backoff_s() > 0 ? e.max_reconnect_backoff_s() : 2.0;
}

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

StatusOr<std::string> ChannelServiceConfig(const v1::ServiceEndpoint& endpoint,
                                           const char* field) {
  std::string policy = endpoint.lb_policy();
  if (policy.empty()) {
    policy = endpoint.address().rfind("unix:", 0) == 0 ? "pick_first" : "round_robin";
  }
  if (policy != "round_robin" && policy != "pick_first") {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ".lb_policy: '", policy, "' is not a policy (round_robin or pick_first)"));
  }
  // Round robin skips replicas whose grpc.health.v1 (whole server) is not
  // SERVING, e.g. one draining after SIGTERM. Calls to the stateless
  // services that fail UNAVAILABLE before the replica answered (it died with
  // the call on the wire) are tried again on another pick.
  std::string config = absl::StrCat(R"({"loadBalancingConfig":[{")", policy, R"(":{}}])");
  if (policy == "round_robin") absl::StrAppend(&config, R"(,"healthCheckConfig":{"serviceName":""})");
  absl::StrAppend(&config, R"(,"methodConfig":[{"name":[)");
  const char* services[] = {pr::ProsodyService::service_full_name(),
                            inf::InferenceService::service_full_name(),
                            pl::PlannerService::service_full_name(),
                            ct::CubeTrackerService::service_full_name()};
  for (std::size_t i = 0; i < std::size(services); ++i) {
    absl::StrAppend(&config, i == 0 ? "" : ",", R"({"service":")", services[i], R"("})");
  }
  absl::StrAppend(&config, R"(],"retryPolicy":{"maxAttempts":3,"initialBackoff":"0.02s",)",
                  R"("maxBackoff":"0.2s","backoffMultiplier":2,"retryableStatusCodes":["UNAVAILABLE"]}}]})");
  return config;
}

StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const v1::ServiceEndpoint& endpoint,
                                                     std::uint32_t max_message_bytes,
                                                     const char* field) {
  if (endpoint.address().empty()) return std::shared_ptr<grpc::Channel>();
  grpc::ChannelArguments args = server::ChannelArgsForMessageLimit(max_message_bytes);
  KINEMO_ASSIGN_OR_RETURN(const std::string service_config, ChannelServiceConfig(endpoint, field));
  args.SetServiceConfigJSON(service_config);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS,
              static_cast<int>(EndpointBackoff(endpoint) * 1000));
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 50);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 50);
  KINEMO_ASSIGN_OR_RETURN(auto creds, MakeChannelCredentials(ClientTlsFilesAt(
                                            field, endpoint.ca_file(), endpoint.cert_file(),
                                            endpoint.key_file())));
  return grpc::CreateCustomChannel(endpoint.address(), creds, args);
}

// ---------------------------------------------------------------------------
// Cube attachment (core/cube_attachment.h) over CubeTrackerService.TrackSource.

namespace {

// One TrackSource stream; a frame at least every stream_idle_s (IdleGuard).
class TrackSourceFeed final : public CubeFeed {
 public:
  TrackSourceFeed(ct::CubeTrackerService::Stub* stub, const ct::TrackSourceRequest& request, Watchdog* watchdog,
                  double idle_s)
      : reader_(stub->TrackSource(&ctx_, request)), idle_(watchdog, &ctx_, idle_s) {}
  bool Read(ct::TrackResponse* response) override {
    if (!reader_->Read(response)) return false;
    idle_.Touch();
    return true;
  }
  Status Finish() override { return FromGrpcStatus(reader_->Finish()); }
  bool idle_expired() const override { return idle_.expired(); }
  void Cancel() override { ctx_.TryCancel(); }

 private:
  grpc::ClientContext ctx_;
  std::unique_ptr<grpc::ClientReader<ct::TrackResponse>> reader_;
  IdleGuard idle_;
};

}  // namespace

std::unique_ptr<CubeAttachment> CoordinatorServiceImpl::NewCubeAttachment(const std::string& session_id,
                                                                          ct::TrackSourceRequest request,
                                                                          bool confirm) {
  OpenCubeFeed open = [stub = cube_tracker_.get(), watchdog = watchdog_.get(),
                       idle_s = deadlines_.stream_idle_s](const ct::TrackSourceRequest& r) {
    return std::make_unique<TrackSourceFeed>(stub, r, watchdog, idle_s);
  };
  return std::make_unique<CubeAttachment>(session_id, std::move(request), std::move(open), manager_.get(),
                                          EndpointBackoff(options_.services().cube_tracker()), confirm,
                                          deadlines_.stream_idle_s);
}

// ---------------------------------------------------------------------------

StatusOr<std::shared_ptr<CoordinatorServiceImpl>> CoordinatorServiceImpl::Create(
    const v1::CoordinatorOptions& options, ServiceChannels channels, const Clock* clock) {
  SessionManagerOptions so;
  KINEMO_ASSIGN_OR_RETURN(so.emotion, ResolveEmotionParams(options.emotion()));
  so.max_sessions = options.max_sessions() > 0 ? options.max_sessions() : 10000;
  so.exclusive_robots = options.exclusive_robots();
  if (!(options.session_idle_timeout_s() >= 0)) {
    return absl::InvalidArgumentError("session_idle_timeout_s: must be >= 0");
  }
  so.idle_timeout_s = options.session_idle_timeout_s();
  if (!(options.resend_s() >= 0)) {
    return absl::InvalidArgumentError("resend_s: must be >= 0");
  }
  KINEMO_ASSIGN_OR_RETURN(const Deadlines deadlines, Deadlines::Resolve(options));
  const std::uint32_t limit = options.server().max_message_bytes();
  const auto& sv = options.services();
  auto fill = [&](std::shared_ptr<grpc::Channel>* ch, const v1::ServiceEndpoint& e,
                  const char* field) -> Status {
    if (*ch) return absl::OkStatus();
    if (!(e.deadline_s() >= 0) || !(e.max_reconnect_backoff_s() >= 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ": deadline_s and max_reconnect_backoff_s must be >= 0"));
    }
    KINEMO_ASSIGN_OR_RETURN(*ch, MakeChannel(e, limit, field));
    return absl::OkStatus();
  };
  KINEMO_RETURN_IF_ERROR(fill(&channels.prosody, sv.prosody(), "services.prosody"));
  KINEMO_RETURN_IF_ERROR(fill(&channels.inference, sv.inference(), "services.inference"));
  KINEMO_RETURN_IF_ERROR(fill(&channels.planner, sv.planner(), "services.planner"));
  KINEMO_RETURN_IF_ERROR(fill(&channels.cube_tracker, sv.cube_tracker(), "services.cube_tracker"));
  KINEMO_RETURN_IF_ERROR(fill(&channels.robot_bridge, sv.robot_bridge(), "services.robot_bridge"));
  std::unique_ptr<SessionStore> store;
  if (!options.store_dir().empty()) {
    KINEMO_ASSIGN_OR_RETURN(store, SqliteSessionStore::Open(options.store_dir(), "store_dir"));
  }
  std::shared_ptr<CoordinatorServiceImpl> impl(
      new CoordinatorServiceImpl(options, so, deadlines, std::move(channels), clock, std::move(store)));
  // Durable sessions come back: relays resume with the restored emotion,
  // cube attachments re-subscribe.
  auto cubes = impl->manager_->Restore();
  if (!cubes.ok()) {
    impl->Stop();
    return Annotate(cubes.status(), "store_dir: restoring the sessions");
  }
  for (const RestoredCube& c : *cubes) {
    if (!impl->cube_tracker_) {
      log::Warn("cube_not_restored", {{"session_id", c.session_id}, {"why", "no cube_tracker"}});
      continue;
    }
    ct::TrackSourceRequest track;
    *track.mutable_source() = c.source;
    *track.mutable_config() = c.config;
    std::lock_guard<std::mutex> l(impl->cubes_mu_);
    impl->cubes_[c.session_id] = impl->NewCubeAttachment(c.session_id, std::move(track), false);
  }
  if (impl->manager_->persistent()) {
    log::Info("sessions_restored", {{"store", options.store_dir()}, {"sessions", impl->manager_->size()},
                                    {"cubes", cubes->size()}});
  }
  return impl;
}

CoordinatorServiceImpl::CoordinatorServiceImpl(const v1::CoordinatorOptions& options,
                                               const SessionManagerOptions& so,
                                               const Deadlines& deadlines, ServiceChannels channels,
                                               const Clock* clock, std::unique_ptr<SessionStore> store)
    : options_(options),
      deadlines_(deadlines),
      watchdog_(std::make_unique<Watchdog>(Watchdog::PeriodFor(deadlines.stream_idle_s))),
      clock_(clock),
      channels_(std::move(channels)),
      store_(std::move(store)) {
  SessionManager::RobotSink sink;
  if (channels_.robot_bridge) {
    RobotRelayOptions ro;
    ro.deadline_s = deadlines_.Short(options_.services().robot_bridge());
    ro.watchdog = watchdog_.get();
    ro.stream_idle_s = deadlines_.stream_idle_s;
    ro.max_backoff_s = EndpointBackoff(options_.services().robot_bridge());
    ro.resend_s = options_.resend_s() > 0 ? options_.resend_s() : 1.0;
    relay_ = std::make_unique<RobotRelay>(channels_.robot_bridge, ro, clock_);
    sink = [relay = relay_.get()](const RobotCommand& c) { relay->Command(c); };
  }
  manager_ = std::make_unique<SessionManager>(so, clock_, std::move(sink), store_.get());
  if (relay_) relay_->SetManager(manager_.get());
  if (channels_.prosody) prosody_ = pr::ProsodyService::NewStub(channels_.prosody);
  if (channels_.inference) inference_ = inf::InferenceService::NewStub(channels_.inference);
  if (channels_.planner) planner_ = pl::PlannerService::NewStub(channels_.planner);
  if (channels_.cube_tracker) {
    cube_tracker_ = ct::CubeTrackerService::NewStub(channels_.cube_tracker);
  }
  ticker_ = std::thread([this] { TickLoop(); });
  metrics_.push_back(metrics::OnScrape(
      "kinemo_coordinator_sessions", "Vleo-Pleo sessions open.", prometheus::MetricType::Gauge,
      [this](std::vector<metrics::Sample>* out) { out->push_back({{}, static_cast<double>(manager_->size())}); }));
  metrics_.push_back(metrics::OnScrape(
      "kinemo_coordinator_streams", "StreamAnimate calls running.", prometheus::MetricType::Gauge,
      [this](std::vector<metrics::Sample>* out) { out->push_back({{}, static_cast<double>(streams_.load())}); }));
}

CoordinatorServiceImpl::~CoordinatorServiceImpl() { Stop(); }

void CoordinatorServiceImpl::Stop() {
  if (stopped_.exchange(true)) return;
  metrics_.clear();
  std::map<std::string, std::unique_ptr<CubeAttachment>> cubes;
  {
    std::lock_guard<std::mutex> l(cubes_mu_);
    cubes.swap(cubes_);
  }
  for (auto& [id, c] : cubes) c->Stop();
  cubes.clear();
  // With a store, sessions (and their cube attachments) stay for the next
  // start; without one they end here, and watchers are told.
  if (!manager_->persistent()) manager_->CloseAll();
  {
    std::lock_guard<std::mutex> l(tick_mu_);
    stopping_ = true;
  }
  tick_cv_.notify_all();
  if (ticker_.joinable()) ticker_.join();
  if (relay_) relay_->Stop();
  watchdog_->Stop();
}

void CoordinatorServiceImpl::TickLoop() {
  const double tick_s = manager_ ? ResolveEmotionParams(options_.emotion())->tick_s : 0.05;
  std::unique_lock<std::mutex> l(tick_mu_);
  while (!stopping_) {
    l.unlock();
    for (const std::string& id : manager_->Tick()) DetachCubeOf(id);  // idle sessions closed
    const double now = clock_->MonotonicS();
    const double next = std::min(now + tick_s, manager_->NextChangeTime());
    l.lock();
    if (stopping_) break;
    // Wake at the next predicted emotion change (exact), at the latest one tick later.
    tick_cv_.wait_for(l, std::chrono::duration<double>(std::max(0.0, next - now)));
  }
}

void CoordinatorServiceImpl::WakeTicker() { tick_cv_.notify_all(); }

std::chrono::system_clock::time_point CoordinatorServiceImpl::DeadlineAfter(double seconds) {
  return std::chrono::system_clock::now() +
         std::chrono::microseconds(static_cast<std::int64_t>(seconds * 1e6));
}

// ---- Sessions -------------------------------------------------------------

grpc::Status CoordinatorServiceImpl::OpenSession(grpc::ServerContext*,
                                                 const v1::OpenSessionRequest* request,
                                                 v1::OpenSessionResponse* response) {
  auto s = manager_->Open(*request);
  if (!s.ok()) return ToGrpcStatus(s.status());
  *response->mutable_session() = *s;
  log::Debug("session_opened", {{"session_id", s->session_id()}, {"robot_id", s->robot_id()},
                               {"request_id", request->request_id()}});
  return grpc::Status::OK;
}

void CoordinatorServiceImpl::DetachCubeOf(const std::string& session_id) {
  std::unique_ptr<CubeAttachment> c;
  {
    std::lock_guard<std::mutex> l(cubes_mu_);
    auto it = cubes_.find(session_id);
    if (it == cubes_.end()) return;
    c = std::move(it->second);
    cubes_.erase(it);
  }
  c->Stop();
}

grpc::Status CoordinatorServiceImpl::CloseSession(grpc::ServerContext*,
                                                  const v1::CloseSessionRequest* request,
                                                  v1::CloseSessionResponse* response) {
  if (auto current = manager_->Get(request->session_id()); !current.ok()) {
    return ToGrpcStatus(current.status());
  }
  DetachCubeOf(request->session_id());
  auto s = manager_->Close(request->session_id(), request->reset_robot(), "client");
  if (!s.ok()) return ToGrpcStatus(s.status());
  *response->mutable_session() = *s;
  WakeTicker();
  return grpc::Status::OK;
}

grpc::Status CoordinatorServiceImpl::ListSessions(grpc::ServerContext*,
                                                  const v1::ListSessionsRequest* request,
                                                  v1::ListSessionsResponse* response) {
  for (auto& s : manager_->List(request->robot_id())) *response->add_sessions() = std::move(s);
  return grpc::Status::OK;
}

grpc::Status CoordinatorServiceImpl::GetSession(grpc::ServerContext*,
                                                const v1::GetSessionRequest* request,
                                                v1::Session* response) {
  auto s = manager_->Get(request->session_id());
  if (!s.ok()) return ToGrpcStatus(s.status());
  *response = *s;
  return grpc::Status::OK;
}

grpc::Status CoordinatorServiceImpl::Act(grpc::ServerContext*, const v1::ActRequest* request,
                                         v1::ActResponse* response) {
  auto s = manager_->Act(request->session_id(), request->action(), request->intensity(), false);
  if (!s.ok()) return ToGrpcStatus(s.status());
  *response->mutable_session() = *s;
  WakeTicker();  // the next emotion change may now be earlier
  return grpc::Status::OK;
}

grpc::Status CoordinatorServiceImpl::WatchSession(grpc::ServerContext* context,
                                                  const v1::WatchSessionRequest* request,
                                                  grpc::ServerWriter<v1::SessionEvent>* writer) {
  std::mutex mu;
  std::condition_variable cv;
  std::deque<v1::SessionEvent> queue;
  bool closed = false;
  constexpr std::size_t kMaxQueued = 10000;
  bool overflow = false;
  const std::string filter = request->session_id();
  auto id = manager_->Subscribe(filter, [&](const v1::SessionEvent& e) {
    std::lock_guard<std::mutex> l(mu);
    if (queue.size() >= kMaxQueued) {
      overflow = true;
    } else {
      queue.push_back(e);
    }
    if (!filter.empty() && e.has_session_closed()) closed = true;
    cv.notify_all();
  });
  if (!id.ok()) return ToGrpcStatus(id.status());
  grpc::Status result = grpc::Status::OK;
  std::unique_lock<std::mutex> l(mu);
  while (true) {
    cv.wait_for(l, std::chrono::milliseconds(100),
                [&] { return !queue.empty() || overflow || context->IsCancelled(); });
    if (context->IsCancelled()) {
      result = grpc::Status(grpc::StatusCode::CANCELLED, "cancelled by the client");
      break;
    }
    if (overflow) {
      result = grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                            "WatchSession: the client reads too slowly (10000 events queued)");
      break;
    }
    if (queue.empty()) continue;
    v1::SessionEvent e = std::move(queue.front());
    queue.pop_front();
    const bool last = closed && queue.empty();
    l.unlock();
    const bool ok = writer->Write(e);
    l.lock();
    if (!ok) {
      result = grpc::Status(grpc::StatusCode::CANCELLED, "stream closed");
      break;
    }
    if (last) break;
  }
  l.unlock();
  manager_->Unsubscribe(*id);
  return result;
}

grpc::Status CoordinatorServiceImpl::AttachCube(grpc::ServerContext*,
                                                const v1::AttachCubeRequest* request,
                                                v1::AttachCubeResponse* response) {
  if (!cube_tracker_) return Unavailable("cube_tracker");
  auto current = manager_->Get(request->session_id());
  if (!current.ok()) return ToGrpcStatus(current.status());
  if (request->source().source_case() == ct::VideoSource::SOURCE_NOT_SET) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "source: video_file or device is required");
  }
  // A camera opens once: its previous attachment stops first. Otherwise the
  // previous attachment runs on until the new source is accepted (a refused
  // one changes nothing).
  const bool device = request->source().source_case() == ct::VideoSource::kDevice;
  if (device) DetachCubeOf(request->session_id());
  ct::TrackSourceRequest track;
  *track.mutable_source() = request->source();
  *track.mutable_config() = request->config();
  // The tracker must answer now, and accept the source: its first answer
  // (a tracked frame, or its error) is awaited here; later outages are
  // retried in the background. (A channel's connectivity cannot be watched
  // on the all-in-one's in-process channel.)
  std::unique_ptr<CubeAttachment> attachment = NewCubeAttachment(request->session_id(), std::move(track), true);
  if (Status first = attachment->WaitFirst(DeadlineAfter(deadlines_.Short(options_.services().cube_tracker())));
      !first.ok()) {
    attachment->Stop();
    if (device) {
      (void)manager_->DetachCube(request->session_id(), absl::StrCat("AttachCube refused: ", first.message()));
    }
    return ToGrpcStatus(first);
  }
  DetachCubeOf(request->session_id());
  // The first frame's face and intensity are the attach's first state.
  auto s = manager_->AttachCube(request->session_id(), request->source(), request->config(),
                                attachment->first_state());
  if (!s.ok()) {
    attachment->Stop();
    return ToGrpcStatus(s.status());
  }
  attachment->Go();
  {
    std::lock_guard<std::mutex> l(cubes_mu_);
    cubes_[request->session_id()] = std::move(attachment);
  }
  *response->mutable_session() = *s;
  return grpc::Status::OK;
}

grpc::Status CoordinatorServiceImpl::DetachCube(grpc::ServerContext*,
                                                const v1::DetachCubeRequest* request,
                                                v1::DetachCubeResponse* response) {
  auto current = manager_->Get(request->session_id());
  if (!current.ok()) return ToGrpcStatus(current.status());
  DetachCubeOf(request->session_id());
  auto s = manager_->DetachCube(request->session_id(), "");
  if (!s.ok()) return ToGrpcStatus(s.status());
  *response->mutable_session() = *s;
  return grpc::Status::OK;
}

// ---- Speech -> animation --------------------------------------------------

grpc::Status CoordinatorServiceImpl::Animate(grpc::ServerContext* context,
                                             const v1::AnimateRequest* request,
                                             v1::AnimateResponse* response) {
  const auto t0 = std::chrono::steady_clock::now();
  if (request->audio().data().empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "audio.data: empty");
  }
  auto method = ResolveMethod(request->method(), options_.animate().default_method(), "method");
  if (!method.ok()) return ToGrpcStatus(method.status());
  if (!v1::Method_IsValid(request->method())) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "method: unknown value");
  }
  if (!prosody_) return Unavailable("prosody");
  if (!planner_) return Unavailable("planner");
  const bool gc = *method == v1::METHOD_GESTURE_CONTROLLER;
  if (gc && !inference_) return Unavailable("inference");
  auto models = ResolveAnimateModels(*request, options_.animate(), *method, "models");
  if (!models.ok()) return ToGrpcStatus(models.status());
  const std::string request_id =
      request->request_id().empty() ? absl::StrCat("animate-", clock_->WallUnixNs())
                                    : request->request_id();
  // Analysis deadlines (deadlines.analysis_*), scaled by the audio's
  // duration: estimated from the payload for prosody (16-bit mono 16 kHz ≈
  // 32 kB/s, the smallest common encoding: an over-estimate for the others),
  // then the duration prosody measured. The caller's deadline, when
  // shorter, wins.
  double audio_s = request->audio().data().size() / 32000.0;
  // One stage's call: its deadline, and the time it took into `*time_s`.
  auto call = [&](auto method_call, const auto& req, auto* res, auto set_time_s) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::min(DeadlineAfter(deadlines_.Analysis(audio_s)), context->deadline()));
    const auto t = std::chrono::steady_clock::now();
    grpc::Status s = method_call(&ctx, req, res);
    if (s.ok()) (response->mutable_times()->*set_time_s)(SecondsSince(t));
    return s;
  };
  using Times = v1::StageTimes;

  // 1. Prosody.
  pr::AnalyzeResponse ares;
  grpc::Status s = call([&](auto* c, const auto& q, auto* r) { return prosody_->Analyze(c, q, r); },
                        AnalyzeRequestFor(*request, *method, request_id), &ares, &Times::set_prosody_s);
  if (!s.ok()) return WithChunkedRemedy(Downstream("prosody", RenameField(s, "face.model_id", "face_model_id")));
  const pr::ProsodyTrack& track = ares.track();
  if (Status d = CheckAnimateDuration(track, options_.animate()); !d.ok()) return ToGrpcStatus(d);
  response->mutable_times()->set_prosody_s(SecondsSince(t0));
  audio_s = track.duration_s();

  if (gc) {
    // 2. Inference: smoothed beliefs per step.
    auto ireq = InferRequestFor(track, models->inference_model_id, request_id);
    if (!ireq.ok()) return ToGrpcStatus(ireq.status());
    inf::InferResponse ires;
    s = call([&](auto* c, const auto& q, auto* r) { return inference_->Infer(c, q, r); }, *ireq, &ires,
             &Times::set_inference_s);
    if (!s.ok()) return Downstream("inference", s);
    // 3. Planner: Gesture Controller synthesis.
    auto sreq = SynthesizeRequestFor(*request, track, *ireq, ires, models->controller_id, request_id);
    if (!sreq.ok()) return ToGrpcStatus(sreq.status());
    pl::SynthesizeResponse sres;
    s = call([&](auto* c, const auto& q, auto* r) { return planner_->Synthesize(c, q, r); }, *sreq, &sres,
             &Times::set_planner_s);
    if (!s.ok()) return WithChunkedRemedy(Downstream("planner", RenameField(s, "rig_id", "models.rig_id")));
    *response->mutable_motion() = std::move(*sres.mutable_motion());
    *response->mutable_segments() = sres.segments();
    if (request->visemes()) {
      pl::VisemesResponse vres;
      s = call([&](auto* c, const auto& q, auto* r) { return planner_->Visemes(c, q, r); },
               VisemesRequestFor(*request, track), &vres, &Times::set_visemes_s);
      if (!s.ok()) return Downstream("planner", s);
      *response->mutable_visemes() = std::move(*vres.mutable_track());
    }
  } else {
    // 2'. Planner: pitch accents -> GMG / BodySpeech (+ visemes in one call).
    pl::SynthesizeGesturesResponse gres;
    s = call([&](auto* c, const auto& q, auto* r) { return planner_->SynthesizeGestures(c, q, r); },
             GesturesRequestFor(*request, track, *method, models->gesture_graph_id, request_id), &gres,
             &Times::set_planner_s);
    if (!s.ok()) return WithChunkedRemedy(Downstream("planner", RenameField(s, "rig_id", "models.rig_id")));
    *response->mutable_motion() = std::move(*gres.mutable_motion());
    *response->mutable_accent_report() = gres.report();
    if (request->visemes()) *response->mutable_visemes() = std::move(*gres.mutable_visemes());
  }
  if (Status f = FinishAnimateResponse(*request, track, *method, request_id, response); !f.ok()) {
    return ToGrpcStatus(f);
  }
  response->mutable_times()->set_total_s(SecondsSince(t0));
  log::Info("animated", {{"request_id", request_id},
                         {"method", v1::Method_Name(*method)},
                         {"duration_s", track.duration_s()},
                         {"total_s", response->times().total_s()}});
  return grpc::Status::OK;
}

// StreamAnimate: stream_animate.cc.

}  // namespace kinemo::coordinator
