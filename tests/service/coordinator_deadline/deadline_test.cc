// Frozen peers (`ctest -L deadline`): real gRPC servers that accept a call
// and never answer, or stop reading their stream, in place of one service;
// the others are the real live stack (live_stack.h). The coordinator must
// answer DEADLINE_EXCEEDED (or UNAVAILABLE for a peer it cannot reach)
// naming the service, within the bound of the call's class
// (CoordinatorOptions.deadlines, set small here), cancel the frozen call,
// and stay healthy: health SERVING, calls to healthy peers still work. A
// session whose robot bridge is frozen still answers Act at once and reports
// the robot's failure in its events; its status watch is ended by the idle
// timeout and opened again.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "common/testing/process.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/coordinator/client/live_client.h"
#include "services/coordinator/coordinator_service.h"
#include "services/coordinator/forwarder.h"
#include "tests/service/coordinator/fakes.h"
#include "tests/service/coordinator/live_stack.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
namespace pr = ::kinemo::prosody::v1;
namespace pl = ::kinemo::planner::v1;
namespace rb = ::kinemo::robot_bridge::v1;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

const std::string kSpeech = kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav";

double Since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// What a frozen peer saw: calls that arrived, and calls its caller cancelled
// (the only way they end).
struct Seen {
  std::mutex mu;
  std::condition_variable cv;
  int calls = 0, cancelled = 0;
  void Call() {
    std::lock_guard<std::mutex> l(mu);
    ++calls;
    cv.notify_all();
  }
  void Cancelled() {
    std::lock_guard<std::mutex> l(mu);
    ++cancelled;
    cv.notify_all();
  }
  // Waits until `pred` holds (false after `timeout`).
  template <typename Pred>
  bool WaitFor(Pred pred, std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> l(mu);
    return cv.wait_for(l, timeout, [&] { return pred(*this); });
  }
};

// A call that is never answered: it ends only when its caller cancels it
// (or its deadline passes). `Base`: the reactor's kind.
template <typename Base>
class Never : public Base {
 public:
  explicit Never(Seen* seen) : seen_(seen) { seen_->Call(); }
  void OnCancel() override {
    seen_->Cancelled();
    this->Finish(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled"));
  }
  void OnDone() override { delete this; }

 private:
  Seen* seen_;
};

using NeverUnary = Never<grpc::ServerUnaryReactor>;
template <typename Resp>
using NeverWrites = Never<grpc::ServerWriteReactor<Resp>>;

// A bidi stream that never answers: it reads every message (`deaf` = only
// the first, then it stops reading, so its caller's writes back up).
template <typename Req, typename Resp>
class NeverAnswers final : public Never<grpc::ServerBidiReactor<Req, Resp>> {
 public:
  NeverAnswers(Seen* seen, bool deaf) : Never<grpc::ServerBidiReactor<Req, Resp>>(seen), deaf_(deaf) {
    this->StartRead(&in_);
  }
  void OnReadDone(bool ok) override {
    if (ok && !deaf_) this->StartRead(&in_);
  }

 private:
  const bool deaf_;
  Req in_;
};

// Prosody: Analyze never answered; StreamAnalyze reads its config, then
// stops reading.
class FrozenProsody final : public pr::ProsodyService::CallbackService {
 public:
  Seen analyze, stream;
  grpc::ServerUnaryReactor* Analyze(grpc::CallbackServerContext*, const pr::AnalyzeRequest*,
                                    pr::AnalyzeResponse*) override {
    return new NeverUnary(&analyze);
  }
  grpc::ServerBidiReactor<pr::StreamAnalyzeRequest, pr::StreamAnalyzeResponse>* StreamAnalyze(
      grpc::CallbackServerContext*) override {
    return new NeverAnswers<pr::StreamAnalyzeRequest, pr::StreamAnalyzeResponse>(&stream, /*deaf=*/true);
  }
};

// Planner: Control reads everything and never answers (not even the header).
class FrozenPlanner final : public pl::PlannerService::CallbackService {
 public:
  Seen control;
  grpc::ServerBidiReactor<pl::ControlRequest, pl::ControlResponse>* Control(grpc::CallbackServerContext*) override {
    return new NeverAnswers<pl::ControlRequest, pl::ControlResponse>(&control, /*deaf=*/false);
  }
};

// Robot bridge: SetEmotion never answered, WatchStatus never sends.
class FrozenBridge final : public rb::RobotBridgeService::CallbackService {
 public:
  Seen set, watch;
  grpc::ServerUnaryReactor* SetEmotion(grpc::CallbackServerContext*, const rb::SetEmotionRequest*,
                                       rb::SetEmotionResponse*) override {
    return new NeverUnary(&set);
  }
  grpc::ServerWriteReactor<rb::RobotStatus>* WatchStatus(grpc::CallbackServerContext*,
                                                         const rb::WatchStatusRequest*) override {
    return new NeverWrites<rb::RobotStatus>(&watch);
  }
};

std::shared_ptr<grpc::Channel> ChannelTo(const server::ServiceHost& host) {
  return grpc::CreateChannel(host.address(), grpc::InsecureChannelCredentials());
}

// A coordinator (with its forwarder, as main.cc serves it) on loopback TCP.
struct Coordinator {
  std::shared_ptr<CoordinatorServiceImpl> service;
  std::unique_ptr<server::ServiceHost> host;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<v1::CoordinatorService::Stub> stub;
  Coordinator(v1::CoordinatorOptions o, ServiceChannels channels) {
    o.mutable_animate()->mutable_models()->set_inference_model_id("crf");
    o.mutable_animate()->mutable_models()->set_controller_id("ctrl");
    auto c = CoordinatorServiceImpl::Create(o, channels);
    EXPECT_TRUE(c.ok()) << c.status();
    if (!c.ok()) return;
    service = *c;
    host = Host({{service, v1::CoordinatorService::service_full_name()},
                 {.generic = Forwarder::ForCoordinator(o, service->channels())}});
    channel = ChannelTo(*host);
    stub = v1::CoordinatorService::NewStub(channel);
  }
  ~Coordinator() {
    if (host) host->Shutdown();
    if (service) service->Stop();
  }
  // Health SERVING, and a call through it to a healthy peer (the real
  // inference service, forwarded) works.
  void ExpectHealthy() {
    EXPECT_TRUE(kinemo::testing::WaitForServing(channel, v1::CoordinatorService::service_full_name(), 5000ms).ok());
    auto inference = inference::v1::InferenceService::NewStub(channel);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 10s);
    inference::v1::ListModelsRequest req;
    inference::v1::ListModelsResponse resp;
    const grpc::Status s = inference->ListModels(&ctx, req, &resp);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_GE(resp.models_size(), 1);
  }
};

class FrozenPeer : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!LiveStack::Get().error.empty()) FAIL() << "live stack: " << LiveStack::Get().error;
    live_ = LiveStack::Get().services->InProcessChannel();
  }
  std::shared_ptr<grpc::Channel> live_;
};

v1::AnimateRequest SpeechRequest() {
  v1::AnimateRequest r;
  r.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
  r.mutable_audio()->set_data(testing::ReadFileBytes(kSpeech));
  r.set_method(v1::METHOD_GESTURE_CONTROLLER);
  return r;
}

TEST_F(FrozenPeer, AnimateAnswersDeadlineExceededWithinTheAnalysisBoundAndStaysHealthy) {
  auto prosody = std::make_shared<FrozenProsody>();
  auto frozen = Host({{prosody, pr::ProsodyService::service_full_name()}});
  v1::CoordinatorOptions o;
  o.mutable_deadlines()->set_analysis_base_s(1);
  o.mutable_deadlines()->set_analysis_per_audio_s(0.1);
  o.mutable_animate()->set_max_audio_s(10);
  Coordinator co(o, {ChannelTo(*frozen), live_, live_, nullptr, nullptr});
  const v1::AnimateRequest request = SpeechRequest();
  // The analysis bound: base + per second of audio (the payload's estimate,
  // 32 kB/s) — the client's own deadline is far longer.
  const double bound_s = 1 + 0.1 * static_cast<double>(request.audio().data().size()) / 32000.0;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 60s);
  v1::AnimateResponse resp;
  const auto t0 = Clock::now();
  const grpc::Status s = co.stub->Animate(&ctx, request, &resp);
  const double took_s = Since(t0);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << s.error_message();
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "prosody")) << s.error_message();
  EXPECT_GE(took_s, bound_s - 0.05);
  EXPECT_LT(took_s, bound_s + 10) << "far past the analysis bound";
  // The frozen call itself ended (the deadline reached the peer).
  EXPECT_TRUE(prosody->analyze.WaitFor([](Seen& x) { return x.cancelled >= 1; }, 10000ms));

  // A forwarded call carries its class's bound too when its caller sets none:
  // analysis at animate.max_audio_s = 1 + 0.1 × 10 s.
  {
    auto stub = pr::ProsodyService::NewStub(co.channel);
    grpc::ClientContext fctx;  // no deadline
    pr::AnalyzeRequest areq;
    *areq.mutable_audio() = request.audio();
    pr::AnalyzeResponse ares;
    const auto t1 = Clock::now();
    const grpc::Status fs = stub->Analyze(&fctx, areq, &ares);
    EXPECT_EQ(fs.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << fs.error_message();
    EXPECT_LT(Since(t1), 2.0 + 10) << "the forwarded call was not bounded";
    EXPECT_TRUE(prosody->analyze.WaitFor([](Seen& x) { return x.cancelled >= 2; }, 10000ms));
  }
  co.ExpectHealthy();

  // A peer that cannot be reached: UNAVAILABLE naming it, at once.
  frozen->Shutdown();
  {
    grpc::ClientContext uctx;
    uctx.set_deadline(std::chrono::system_clock::now() + 60s);
    const grpc::Status us = co.stub->Animate(&uctx, request, &resp);
    EXPECT_EQ(us.error_code(), grpc::StatusCode::UNAVAILABLE) << us.error_message();
    EXPECT_TRUE(absl::StartsWith(us.error_message(), "prosody")) << us.error_message();
  }
  co.ExpectHealthy();
}

// The live client's stream against `co`, as fast as the coordinator takes
// the chunks.
StatusOr<LiveStreamResult> Stream(Coordinator& co) {
  auto audio = audio::DecodeAudioFile(kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav");
  if (!audio.ok()) return audio.status();
  LiveStreamOptions lo;
  lo.realtime = false;
  lo.timeout_s = 120;
  return RunLiveStream(co.channel, audio->samples, audio->sample_rate_hz, lo);
}

// A stream through a coordinator over `channels` (one of them frozen, its
// calls seen by `seen`) ends with DEADLINE_EXCEEDED naming `service` after
// the idle timeout (1 s), cancels the frozen call, and the coordinator stays
// healthy.
void ExpectStreamEndsOnIdle(const ServiceChannels& channels, const std::string& service, Seen* seen) {
  v1::CoordinatorOptions o;
  o.mutable_deadlines()->set_stream_idle_s(1);
  Coordinator co(o, channels);
  const auto t0 = Clock::now();
  auto r = Stream(co);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kDeadlineExceeded) << r.status();
  EXPECT_TRUE(absl::StartsWith(r.status().message(), service + ": no progress")) << r.status();
  EXPECT_LT(Since(t0), 1 + 30) << "far past the idle bound";
  EXPECT_TRUE(seen->WaitFor([](Seen& x) { return x.cancelled >= 1; }, 10000ms));
  co.ExpectHealthy();
}

TEST_F(FrozenPeer, StreamAnimateEndsWhenProsodyStopsReadingItsStream) {
  auto prosody = std::make_shared<FrozenProsody>();
  auto frozen = Host({{prosody, pr::ProsodyService::service_full_name()}});
  ExpectStreamEndsOnIdle({ChannelTo(*frozen), live_, live_, nullptr, nullptr}, "prosody", &prosody->stream);
}

TEST_F(FrozenPeer, StreamAnimateEndsWhenThePlannerNeverAnswers) {
  auto planner = std::make_shared<FrozenPlanner>();
  auto frozen = Host({{planner, pl::PlannerService::service_full_name()}});
  ExpectStreamEndsOnIdle({live_, live_, ChannelTo(*frozen), nullptr, nullptr}, "planner", &planner->control);
}

TEST_F(FrozenPeer, SessionActAnswersAndReportsAFrozenRobotBridgeInItsEvents) {
  auto bridge = std::make_shared<FrozenBridge>();
  auto frozen = Host({{bridge, rb::RobotBridgeService::service_full_name()}});
  v1::CoordinatorOptions o;
  o.mutable_deadlines()->set_short_s(0.5);
  o.mutable_deadlines()->set_stream_idle_s(1);
  Coordinator co(o, {live_, live_, live_, nullptr, ChannelTo(*frozen)});
  v1::OpenSessionRequest open;
  open.set_session_id("vleo-1");
  open.set_robot_id("pleo-1");
  open.set_vleo(v1::VLEO_KIND_CUBE);
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 10s);
    v1::OpenSessionResponse opened;
    const grpc::Status s = co.stub->OpenSession(&ctx, open, &opened);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  grpc::ClientContext watch_ctx;
  watch_ctx.set_deadline(std::chrono::system_clock::now() + 30s);
  v1::WatchSessionRequest wreq;
  wreq.set_session_id("vleo-1");
  auto events = co.stub->WatchSession(&watch_ctx, wreq);
  v1::ActRequest act;
  act.set_session_id("vleo-1");
  act.set_action(common::v1::ACTION_KISSES);
  act.set_intensity(1.0);
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 10s);
    v1::ActResponse acted;
    const grpc::Status s = co.stub->Act(&ctx, act, &acted);
    EXPECT_TRUE(s.ok()) << s.error_message();  // the session does not wait on its robot
  }
  // The robot's failure comes as an event: the command's deadline passed.
  v1::SessionEvent e;
  bool reported = false;
  while (!reported && events->Read(&e)) {
    reported = e.has_robot_commanded() && !e.robot_commanded().error().empty();
  }
  ASSERT_TRUE(reported) << "no robot_commanded event with an error";
  EXPECT_TRUE(absl::StartsWith(e.robot_commanded().error(), "robot_bridge")) << e.robot_commanded().error();
  EXPECT_TRUE(absl::StrContains(e.robot_commanded().error(), "eadline")) << e.robot_commanded().error();
  watch_ctx.TryCancel();
  (void)events->Finish();
  // The silent status watch is ended by the idle timeout and opened again.
  EXPECT_TRUE(bridge->watch.WaitFor([](Seen& x) { return x.cancelled >= 1 && x.calls >= 2; }, 20000ms));
  EXPECT_GE(bridge->set.cancelled, 1);
  co.ExpectHealthy();
  grpc::ClientContext ctx;
  v1::GetSessionRequest get;
  get.set_session_id("vleo-1");
  v1::Session session;
  EXPECT_TRUE(co.stub->GetSession(&ctx, get, &session).ok());
}

}  // namespace
}  // namespace kinemo::coordinator
