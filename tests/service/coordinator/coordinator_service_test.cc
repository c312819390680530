// The coordinator service over real gRPC against mock services (real gRPC
// servers on ephemeral ports): the real prosody service analyses real speech;
// inference, planner, robot bridge and cube tracker are fakes that record
// what the coordinator sends. The coordinator's logic is under test.
#include "services/coordinator/coordinator_service.h"

#include <algorithm>
#include <chrono>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "common/server/service_host.h"
#include "gtest/gtest.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "services/coordinator/core/animate_plan.h"
#include "services/prosody/prosody_service.h"
#include "common/motion/bvh.h"
#include "common/testing/process.h"
#include "tests/service/coordinator/face_store.h"
#include "tests/service/coordinator/fakes.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
using namespace std::chrono_literals;
using testing::FakeBridge;
using testing::FakeCubeTracker;
using testing::FakeInference;
using testing::FakePlanner;

const std::string kData = KINEMO_TEST_DATA_DIR;

std::unique_ptr<server::ServiceHost> Host(std::vector<server::HostedService> services,
                                          int port = 0) {
  common::v1::ServerOptions o;
  o.set_host("127.0.0.1");
  o.set_port(port);
  o.set_shutdown_grace_s(0.2);
  auto h = server::ServiceHost::Start(o, "test", std::move(services));
  EXPECT_TRUE(h.ok()) << h.status();
  return h.ok() ? std::move(*h) : nullptr;
}

std::shared_ptr<grpc::Channel> Connect(const std::string& address) {
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(),
                                   server::ChannelArgsForMessageLimit(64 << 20));
}

// Mock services, and the coordinator served on its own port.
struct Stack {
  std::shared_ptr<FakeInference> inference = std::make_shared<FakeInference>();
  std::shared_ptr<FakePlanner> planner = std::make_shared<FakePlanner>(
      testing::ReadFileBytes(kData + "/motion/cmu_007_12_first40.bvh"));
  std::shared_ptr<FakeBridge> bridge = std::make_shared<FakeBridge>();
  std::shared_ptr<FakeCubeTracker> cube = std::make_shared<FakeCubeTracker>();
  std::unique_ptr<server::ServiceHost> mocks;
  std::unique_ptr<server::ServiceHost> bridge_host;
  int bridge_port = 0;
  std::shared_ptr<CoordinatorServiceImpl> coordinator;
  std::unique_ptr<server::ServiceHost> host;
  std::unique_ptr<v1::CoordinatorService::Stub> stub;

  explicit Stack(v1::CoordinatorOptions options = {}, prosody::v1::ProsodyOptions prosody_options = {}) {
    mocks = Host({{std::make_shared<prosody::ProsodyServiceImpl>(prosody_options),
                   prosody::v1::ProsodyService::service_full_name()},
                  {inference, inference::v1::InferenceService::service_full_name()},
                  {planner, planner::v1::PlannerService::service_full_name()},
                  {cube, cube_tracker::v1::CubeTrackerService::service_full_name()}});
    StartBridge();
    auto* sv = options.mutable_services();
    sv->mutable_prosody()->set_address(mocks->address());
    sv->mutable_inference()->set_address(mocks->address());
    sv->mutable_planner()->set_address(mocks->address());
    sv->mutable_cube_tracker()->set_address(mocks->address());
    sv->mutable_cube_tracker()->set_max_reconnect_backoff_s(0.1);
    sv->mutable_robot_bridge()->set_address(bridge_host->address());
    sv->mutable_robot_bridge()->set_max_reconnect_backoff_s(0.1);
    auto c = CoordinatorServiceImpl::Create(options);
    EXPECT_TRUE(c.ok()) << c.status();
    coordinator = *c;
    host = Host({{coordinator, v1::CoordinatorService::service_full_name()}});
    stub = v1::CoordinatorService::NewStub(Connect(host->address()));
  }
  ~Stack() {
    if (host) host->Shutdown();
    coordinator->Stop();
    StopBridge();
    if (mocks) mocks->Shutdown();
  }
  void StartBridge() {
    bridge = std::make_shared<FakeBridge>();
    bridge_host = Host({{bridge, robot_bridge::v1::RobotBridgeService::service_full_name()}},
                       bridge_port);
    ASSERT_NE(bridge_host, nullptr);
    bridge_port = bridge_host->port();
  }
  void StopBridge() {
    if (!bridge_host) return;
    bridge->Stop();
    bridge_host->Shutdown();
    bridge_host.reset();
  }
};

v1::AnimateRequest SpeechRequest(v1::Method method) {
  v1::AnimateRequest r;
  r.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
  r.mutable_audio()->set_data(
      testing::ReadFileBytes(kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav"));
  r.set_method(method);
  r.mutable_models()->set_inference_model_id("m");
  r.mutable_models()->set_controller_id("c");
  r.mutable_models()->set_gesture_graph_id("g");
  r.set_format(common::v1::MOTION_FORMAT_BVH);
  r.set_request_id("req-1");
  return r;
}

TEST(CoordinatorAnimate, GestureControllerRunsProsodyInferencePlannerOnRealSpeech) {
  Stack st;
  v1::AnimateResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 30s);
  grpc::Status s = st.stub->Animate(&ctx, SpeechRequest(v1::METHOD_GESTURE_CONTROLLER), &resp);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(resp.method(), v1::METHOD_GESTURE_CONTROLLER);
  EXPECT_EQ(resp.request_id(), "req-1");
  EXPECT_TRUE(absl::StartsWith(resp.motion().bvh(), "HIERARCHY"));
  const auto& p = resp.prosody();
  EXPECT_GT(p.duration_s(), 3.0);  // the clip is ~7 s of read speech
  EXPECT_GT(p.syllables(), 5u);
  EXPECT_GT(p.voiced_fraction(), 0.2);
  EXPECT_GT(p.f0_mean_hz(), 60.0);
  EXPECT_LT(p.f0_mean_hz(), 400.0);
  // Inference got the syllables plus unvoiced gap steps tiling [0, duration].
  inference::v1::InferRequest infer;
  {
    std::lock_guard<std::mutex> l(st.inference->mu);
    infer = st.inference->last;
  }
  EXPECT_EQ(infer.model_id(), "m");
  EXPECT_EQ(infer.request_id(), "req-1");
  ASSERT_GE(infer.inputs_size(), static_cast<int>(p.syllables()));
  EXPECT_NEAR(infer.inputs(0).start_s(), 0.0, 1e-9);
  int syllable_steps = 0;
  for (int i = 0; i < infer.inputs_size(); ++i) {
    const auto& x = infer.inputs(i);
    EXPECT_GT(x.end_s(), x.start_s());
    if (x.voiced() || x.intensity_mean_db() != 0) {
      ++syllable_steps;
    } else {
      EXPECT_LE(x.end_s() - x.start_s(), kMaxGapStepS + 1e-9);
    }
    if (i > 0) {
      EXPECT_GE(x.start_s(), infer.inputs(i - 1).end_s() - 1e-9);
    }
  }
  EXPECT_EQ(syllable_steps, static_cast<int>(p.syllables()));
  EXPECT_NEAR(infer.inputs(infer.inputs_size() - 1).end_s(), p.duration_s(), 1e-6);
  // The planner got one belief per step and the speech's length.
  planner::v1::SynthesizeRequest synth;
  {
    std::lock_guard<std::mutex> l(st.planner->mu);
    synth = st.planner->last_synthesize;
  }
  EXPECT_EQ(synth.controller_id(), "c");
  ASSERT_EQ(synth.beliefs_size(), infer.inputs_size());
  EXPECT_DOUBLE_EQ(synth.beliefs(3).start_s(), infer.inputs(3).start_s());
  EXPECT_DOUBLE_EQ(synth.beliefs(3).probabilities(0), infer.inputs(3).voiced() ? 0.8 : 0.1);
  EXPECT_NEAR(synth.duration_s(), p.duration_s(), 1e-9);
  EXPECT_EQ(synth.format(), common::v1::MOTION_FORMAT_BVH);
  EXPECT_EQ(resp.segments_size(), 1);
  EXPECT_GT(resp.times().total_s(), 0.0);
  EXPECT_GE(resp.times().total_s(), resp.times().prosody_s());
}

// The face (docs/face.md): with a face model in the prosody service, Animate
// returns one face frame per motion frame (also for BVH text), at the motion's
// times; an unknown face model is refused naming the request's field.
TEST(CoordinatorAnimate, TheFaceComesWithEveryMotionFrame) {
  kinemo::testing::TempDir dir;
  ASSERT_EQ(MakeFaceStore(dir.File("store")), "");
  prosody::v1::ProsodyOptions po;
  po.set_store_dir(dir.File("store"));
  Stack st({}, po);
  v1::AnimateResponse resp;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 30s);
    grpc::Status s = st.stub->Animate(&ctx, SpeechRequest(v1::METHOD_GESTURE_CONTROLLER), &resp);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  // The fake planner's BVH: 40 frames of CMU motion (no jaw joint).
  auto clip = motion::ParseBvh(resp.motion().bvh(), "motion");
  ASSERT_TRUE(clip.ok()) << clip.status();
  ASSERT_EQ(resp.face().frames_size(), clip->num_frames());
  EXPECT_NEAR(resp.face().frame_time_s(), clip->frame_time_s, 1e-9);
  for (int i = 0; i < resp.face().frames_size(); ++i) {
    const auto& f = resp.face().frames(i);
    EXPECT_NEAR(f.time_s(), i * clip->frame_time_s, 1e-9);
    ASSERT_EQ(f.ovr_visemes_size(), 15);
    double sum = 0;
    for (float w : f.ovr_visemes()) sum += w;
    EXPECT_NEAR(sum, 1.0, 1e-3);
  }
  auto req = SpeechRequest(v1::METHOD_GESTURE_CONTROLLER);
  req.set_face_model_id("nobody");
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 30s);
  grpc::Status s = st.stub->Animate(&ctx, req, &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(absl::StrContains(s.error_message(), "face_model_id: no face model 'nobody'")) << s.error_message();
}

TEST(CoordinatorAnimate, GmgGetsThePitchAccentsOfTheSpeech) {
  Stack st;
  for (auto method : {v1::METHOD_GMG, v1::METHOD_BODYSPEECH}) {
    v1::AnimateResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 30s);
    grpc::Status s = st.stub->Animate(&ctx, SpeechRequest(method), &resp);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(resp.method(), method);
    planner::v1::SynthesizeGesturesRequest g;
    {
      std::lock_guard<std::mutex> l(st.planner->mu);
      g = st.planner->last_gestures;
    }
    EXPECT_EQ(g.graph_id(), "g");
    EXPECT_EQ(g.algorithm(), method == v1::METHOD_GMG ? planner::v1::GESTURE_ALGORITHM_GMG
                                                      : planner::v1::GESTURE_ALGORITHM_BODYSPEECH);
    ASSERT_GT(resp.prosody().accents_size(), 0);
    ASSERT_EQ(g.accents_size(), resp.prosody().accents_size());
    EXPECT_DOUBLE_EQ(g.accents(0).time_s(), resp.prosody().accents(0).time_s());
    EXPECT_NEAR(g.duration_s(), resp.prosody().duration_s(), 1e-9);
    EXPECT_EQ(resp.accent_report_size(), g.accents_size());
    EXPECT_EQ(st.inference->calls, 0);  // no inference for the GMG methods
  }
}

TEST(CoordinatorAnimate, ErrorsNameTheFieldOrTheService) {
  Stack st;
  v1::AnimateResponse resp;
  {
    grpc::ClientContext ctx;
    v1::AnimateRequest r = SpeechRequest(v1::METHOD_GMG);
    r.mutable_audio()->clear_data();
    grpc::Status s = st.stub->Animate(&ctx, r, &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "audio.data")) << s.error_message();
  }
  {
    grpc::ClientContext ctx;
    v1::AnimateRequest r = SpeechRequest(v1::METHOD_GESTURE_CONTROLLER);
    r.mutable_models()->clear_controller_id();
    grpc::Status s = st.stub->Animate(&ctx, r, &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "models.controller_id"));
  }
  {
    grpc::ClientContext ctx;
    v1::AnimateRequest r = SpeechRequest(v1::METHOD_GMG);
    r.mutable_audio()->set_data("not audio at all");
    grpc::Status s = st.stub->Animate(&ctx, r, &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "prosody: ")) << s.error_message();
  }
  // A coordinator whose planner is not reachable: UNAVAILABLE, not a hang.
  v1::CoordinatorOptions o;
  o.mutable_services()->mutable_prosody()->set_address(st.mocks->address());
  o.mutable_services()->mutable_planner()->set_address("127.0.0.1:1");
  auto c = CoordinatorServiceImpl::Create(o);
  ASSERT_TRUE(c.ok());
  grpc::ServerContext sctx;
  grpc::Status s = (*c)->Animate(&sctx, &*std::make_unique<v1::AnimateRequest>(
                                            SpeechRequest(v1::METHOD_GMG)),
                                 &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE) << s.error_message();
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "planner: ")) << s.error_message();
}

TEST(CoordinatorStreamAnimate, LivePcmFlowsThroughProsodyInferenceAndTheController) {
  Stack st;
  auto audio = audio::DecodeAudioFile(kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav");
  ASSERT_TRUE(audio.ok()) << audio.status();
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 60s);
  auto stream = st.stub->StreamAnimate(&ctx);
  v1::StreamAnimateRequest cfg;
  cfg.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  cfg.mutable_config()->mutable_format()->set_sample_rate_hz(audio->sample_rate_hz);
  cfg.mutable_config()->mutable_format()->set_channels(1);
  cfg.mutable_config()->mutable_models()->set_inference_model_id("m");
  cfg.mutable_config()->mutable_models()->set_controller_id("c");
  cfg.mutable_config()->set_emit_prosody_events(true);
  ASSERT_TRUE(stream->Write(cfg));
  // 20 ms chunks, written from another thread while this one reads.
  std::thread writer([&] {
    const std::size_t n = static_cast<std::size_t>(audio->sample_rate_hz / 50);
    std::uint64_t seq = 0;
    for (std::size_t i = 0; i < audio->samples.size(); i += n) {
      const std::size_t m = std::min(n, audio->samples.size() - i);
      v1::StreamAnimateRequest q;
      q.mutable_chunk()->set_sequence_number(seq++);
      q.mutable_chunk()->set_start_time_s(static_cast<double>(i) / audio->sample_rate_hz);
      q.mutable_chunk()->set_data(reinterpret_cast<const char*>(&audio->samples[i]), m * sizeof(float));
      if (!stream->Write(q)) return;
    }
    stream->WritesDone();
  });
  v1::StreamAnimateResponse r;
  int headers = 0, accents = 0;
  std::vector<double> frame_times;
  std::uint64_t max_seq = 0;
  while (stream->Read(&r)) {
    if (r.has_header()) {
      ++headers;
      EXPECT_EQ(r.header().skeleton().name(), "c");
      EXPECT_TRUE(frame_times.empty());
    }
    if (r.has_accent()) ++accents;
    for (const auto& f : r.frames().frames()) frame_times.push_back(f.time_s());
    max_seq = std::max(max_seq, r.last_chunk_sequence());
  }
  writer.join();
  grpc::Status s = stream->Finish();
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(headers, 1);
  EXPECT_GT(accents, 0);
  // Frames cover the speech (up to the last syllable or pause) in order.
  ASSERT_FALSE(frame_times.empty());
  EXPECT_TRUE(std::is_sorted(frame_times.begin(), frame_times.end()));
  EXPECT_GT(frame_times.back(), 0.5 * audio->duration_s);
  EXPECT_GT(max_seq, 0u);
  std::lock_guard<std::mutex> l(st.inference->mu);
  EXPECT_EQ(st.inference->stream_model, "m");
  ASSERT_GT(st.inference->streamed.size(), 5u);
  for (std::size_t i = 1; i < st.inference->streamed.size(); ++i) {
    EXPECT_GE(st.inference->streamed[i].start_s(), st.inference->streamed[i - 1].end_s() - 1e-9);
  }
  std::lock_guard<std::mutex> l2(st.planner->mu);
  EXPECT_EQ(st.planner->beliefs.size(), st.inference->streamed.size());
}

TEST(CoordinatorStreamAnimate, GmgIsRefusedLive) {
  Stack st;
  grpc::ClientContext ctx;
  auto stream = st.stub->StreamAnimate(&ctx);
  v1::StreamAnimateRequest cfg;
  cfg.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
  cfg.mutable_config()->mutable_format()->set_sample_rate_hz(16000);
  cfg.mutable_config()->set_method(v1::METHOD_GMG);
  ASSERT_TRUE(stream->Write(cfg));
  stream->WritesDone();
  v1::StreamAnimateResponse r;
  EXPECT_FALSE(stream->Read(&r));
  grpc::Status s = stream->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "config.method"));
}

// A stream refused for its config holds no slot of
// animate.max_concurrent_streams: with one slot, streams refused for
// config.cube_tones (checked after the admission once) leave it free.
TEST(CoordinatorStreamAnimate, AStreamRefusedForItsConfigHoldsNoSlot) {
  v1::CoordinatorOptions o;
  o.mutable_animate()->set_max_concurrent_streams(1);
  Stack st(o);
  auto run = [&](bool bad) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 30s);
    auto stream = st.stub->StreamAnimate(&ctx);
    v1::StreamAnimateRequest cfg;
    cfg.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
    cfg.mutable_config()->mutable_format()->set_sample_rate_hz(16000);
    cfg.mutable_config()->mutable_models()->set_inference_model_id("m");
    cfg.mutable_config()->mutable_models()->set_controller_id("c");
    if (bad) (*cfg.mutable_config()->mutable_cube_tones())["ACTION_SHOUT"] = "excited";
    EXPECT_TRUE(stream->Write(cfg));
    stream->WritesDone();
    v1::StreamAnimateResponse r;
    bool summary = false;
    while (stream->Read(&r)) summary = summary || r.has_summary();
    const grpc::Status s = stream->Finish();
    if (!bad) {
      EXPECT_TRUE(summary);
    }
    return s;
  };
  for (int i = 0; i < 3; ++i) {
    const grpc::Status s = run(true);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "config.cube_tones")) << s.error_message();
  }
  const grpc::Status s = run(false);
  EXPECT_TRUE(s.ok()) << s.error_message();
}

// Reads events until `pred` holds or the deadline passes.
template <typename Pred>
bool ReadUntil(grpc::ClientReader<v1::SessionEvent>* reader, std::vector<v1::SessionEvent>* seen,
               Pred pred) {
  v1::SessionEvent e;
  while (reader->Read(&e)) {
    seen->push_back(e);
    if (pred(e)) return true;
  }
  return false;
}

v1::CoordinatorOptions FastEmotion() {
  v1::CoordinatorOptions o;
  o.mutable_emotion()->set_rate_per_s(2.0);  // angry -> happy in 0.75 s at full intensity
  o.set_resend_s(0.2);
  return o;
}

TEST(CoordinatorSessions, KissesMakePleoHappyAndTheBridgeIsCommanded) {
  Stack st(FastEmotion());
  v1::OpenSessionRequest open;
  open.set_session_id("vleo-1");
  open.set_robot_id("pleo");
  open.set_initial_emotion(common::v1::EMOTION_ANGRY);
  v1::OpenSessionResponse opened;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->OpenSession(&ctx, open, &opened).ok());
  }
  EXPECT_EQ(opened.session().emotion(), common::v1::EMOTION_ANGRY);
  ASSERT_TRUE(st.bridge->WaitFor(common::v1::EMOTION_ANGRY, 1, 5s));

  grpc::ClientContext watch_ctx;
  watch_ctx.set_deadline(std::chrono::system_clock::now() + 20s);
  v1::WatchSessionRequest wreq;
  wreq.set_session_id("vleo-1");
  auto reader = st.stub->WatchSession(&watch_ctx, wreq);
  std::vector<v1::SessionEvent> seen;
  ASSERT_TRUE(ReadUntil(reader.get(), &seen, [](const auto& e) { return e.has_snapshot(); }));

  v1::ActRequest act;
  act.set_session_id("vleo-1");
  act.set_action(common::v1::ACTION_KISSES);
  act.set_intensity(1.0);
  v1::ActResponse acted;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->Act(&ctx, act, &acted).ok());
  }
  ASSERT_TRUE(ReadUntil(reader.get(), &seen, [](const v1::SessionEvent& e) {
    return e.has_robot_commanded() && e.robot_commanded().emotion() == common::v1::EMOTION_HAPPY;
  }));
  std::vector<std::pair<int, double>> changes;
  for (const auto& e : seen) {
    if (e.has_emotion_changed()) {
      changes.push_back({e.emotion_changed().to_emotion(), e.session_time_s()});
    }
  }
  ASSERT_EQ(changes.size(), 2u);
  EXPECT_EQ(changes[0].first, common::v1::EMOTION_NEUTRAL);
  EXPECT_EQ(changes[1].first, common::v1::EMOTION_HAPPY);
  // 1.5 valence units at 2 /s after the Act.
  EXPECT_NEAR(changes[1].second - changes[0].second, 0.8 / 2.0, 1e-6);
  EXPECT_TRUE(st.bridge->WaitFor(common::v1::EMOTION_HAPPY, 1, 5s));
  watch_ctx.TryCancel();
  (void)reader->Finish();

  // Close: the watch of that session ends with SessionClosed.
  grpc::ClientContext w2;
  auto reader2 = st.stub->WatchSession(&w2, wreq);
  std::vector<v1::SessionEvent> seen2;
  ASSERT_TRUE(ReadUntil(reader2.get(), &seen2, [](const auto& e) { return e.has_snapshot(); }));
  v1::CloseSessionRequest close;
  close.set_session_id("vleo-1");
  v1::CloseSessionResponse closed;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->CloseSession(&ctx, close, &closed).ok());
  }
  EXPECT_EQ(closed.session().emotion(), common::v1::EMOTION_HAPPY);
  v1::SessionEvent e;
  while (reader2->Read(&e)) seen2.push_back(e);
  EXPECT_TRUE(reader2->Finish().ok());
  EXPECT_TRUE(seen2.back().has_session_closed());
}

TEST(CoordinatorSessions, ABridgeRestartGetsTheCurrentEmotionAgain) {
  Stack st(FastEmotion());
  v1::OpenSessionRequest open;
  open.set_session_id("vleo-2");
  open.set_robot_id("pleo");
  open.set_initial_emotion(common::v1::EMOTION_HAPPY);
  v1::OpenSessionResponse opened;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->OpenSession(&ctx, open, &opened).ok());
  }
  ASSERT_TRUE(st.bridge->WaitFor(common::v1::EMOTION_HAPPY, 1, 5s));
  st.StopBridge();
  // While the bridge is down the session runs on: shouting makes it angry.
  v1::ActRequest act;
  act.set_session_id("vleo-2");
  act.set_action(common::v1::ACTION_SHOUTING);
  act.set_intensity(1.0);
  v1::ActResponse acted;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->Act(&ctx, act, &acted).ok());
  }
  for (int i = 0; i < 100; ++i) {
    grpc::ClientContext ctx;
    v1::GetSessionRequest g;
    g.set_session_id("vleo-2");
    v1::Session s;
    ASSERT_TRUE(st.stub->GetSession(&ctx, g, &s).ok());
    if (s.emotion() == common::v1::EMOTION_ANGRY) break;
    std::this_thread::sleep_for(50ms);
  }
  // A new bridge on the same port knows nothing; the coordinator re-sends.
  st.StartBridge();
  EXPECT_TRUE(st.bridge->WaitFor(common::v1::EMOTION_ANGRY, 1, 10s));
  grpc::ClientContext ctx;
  v1::GetSessionRequest g;
  g.set_session_id("vleo-2");
  v1::Session s;
  ASSERT_TRUE(st.stub->GetSession(&ctx, g, &s).ok());
  EXPECT_EQ(s.emotion(), common::v1::EMOTION_ANGRY);
}

TEST(CoordinatorSessions, ACubeStreamDrivesTheSessionAndResumesAfterAnOutage) {
  Stack st(FastEmotion());
  cube_tracker::v1::CubeEvent kisses;
  kisses.mutable_action_launched()->set_action(common::v1::ACTION_KISSES);
  kisses.mutable_action_launched()->set_intensity(0.5);
  cube_tracker::v1::CubeEvent louder;
  louder.mutable_intensity_changed()->set_from_intensity(0.5);
  louder.mutable_intensity_changed()->set_to_intensity(1.0);
  st.cube->frames.resize(10);
  st.cube->frames[2].events.push_back(kisses);
  st.cube->frames[7].events.push_back(louder);
  st.cube->fail_after_frames = 5;

  v1::OpenSessionRequest open;
  open.set_session_id("cube-1");
  open.set_robot_id("pleo");
  open.set_vleo(v1::VLEO_KIND_CUBE);
  v1::OpenSessionResponse opened;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->OpenSession(&ctx, open, &opened).ok());
  }
  grpc::ClientContext watch_ctx;
  watch_ctx.set_deadline(std::chrono::system_clock::now() + 20s);
  v1::WatchSessionRequest wreq;
  wreq.set_session_id("cube-1");
  auto reader = st.stub->WatchSession(&watch_ctx, wreq);
  std::vector<v1::SessionEvent> seen;
  ASSERT_TRUE(ReadUntil(reader.get(), &seen, [](const auto& e) { return e.has_snapshot(); }));

  v1::AttachCubeRequest attach;
  attach.set_session_id("cube-1");
  attach.mutable_source()->set_video_file("scripted.mp4");
  v1::AttachCubeResponse attached;
  {
    grpc::ClientContext ctx;
    grpc::Status s = st.stub->AttachCube(&ctx, attach, &attached);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  // The source ends: the cube is detached, saying why.
  ASSERT_TRUE(ReadUntil(reader.get(), &seen, [](const v1::SessionEvent& e) {
    return e.has_cube_status_changed() && !e.cube_status_changed().attached();
  }));
  EXPECT_EQ(seen.back().cube_status_changed().reason(), "source ended");
  std::vector<std::pair<int, double>> actions;
  for (const auto& e : seen) {
    if (e.has_action_changed()) {
      EXPECT_TRUE(e.action_changed().from_cube());
      actions.push_back({e.action_changed().action(), e.action_changed().intensity()});
    }
  }
  ASSERT_EQ(actions.size(), 2u);
  EXPECT_EQ(actions[0], std::make_pair(static_cast<int>(common::v1::ACTION_KISSES), 0.5));
  EXPECT_EQ(actions[1], std::make_pair(static_cast<int>(common::v1::ACTION_KISSES), 1.0));
  {
    std::lock_guard<std::mutex> l(st.cube->mu);
    ASSERT_EQ(st.cube->start_frames.size(), 2u);
    EXPECT_EQ(st.cube->start_frames[1], 5u);  // resumed at the next unprocessed frame
  }
  watch_ctx.TryCancel();
  (void)reader->Finish();
}

// Issue 16: a source the tracker cannot open was answered OK and failed in
// the background; now AttachCube answers the tracker's error and attaches
// nothing.
TEST(CoordinatorSessions, AttachCubeAnswersTheTrackersErrorUpFront) {
  Stack st;
  st.cube->refuse = grpc::Status(grpc::StatusCode::NOT_FOUND, "source.video_file: 'gone.mp4' not found");
  v1::OpenSessionRequest open;
  open.set_session_id("cube-1");
  open.set_robot_id("pleo");
  v1::OpenSessionResponse opened;
  {
    grpc::ClientContext ctx;
    ASSERT_TRUE(st.stub->OpenSession(&ctx, open, &opened).ok());
  }
  v1::AttachCubeRequest attach;
  attach.set_session_id("cube-1");
  attach.mutable_source()->set_video_file("gone.mp4");
  v1::AttachCubeResponse attached;
  grpc::ClientContext ctx;
  const grpc::Status s = st.stub->AttachCube(&ctx, attach, &attached);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(s.error_message(), "source.video_file: 'gone.mp4' not found");
  grpc::ClientContext get_ctx;
  v1::GetSessionRequest g;
  g.set_session_id("cube-1");
  v1::Session session;
  ASSERT_TRUE(st.stub->GetSession(&get_ctx, g, &session).ok());
  EXPECT_FALSE(session.cube_attached());
  EXPECT_EQ(session.vleo(), v1::VLEO_KIND_CLIENT);
  std::lock_guard<std::mutex> l(st.cube->mu);
  EXPECT_EQ(st.cube->start_frames.size(), 1u);  // asked once, not retried
}

TEST(CoordinatorSessions, RequestErrorsAreMapped) {
  Stack st;
  grpc::ClientContext c1;
  v1::ActRequest act;
  act.set_session_id("nope");
  act.set_action(common::v1::ACTION_KISSES);
  v1::ActResponse r;
  EXPECT_EQ(st.stub->Act(&c1, act, &r).error_code(), grpc::StatusCode::NOT_FOUND);
  grpc::ClientContext c2;
  v1::OpenSessionRequest open;
  open.set_robot_id("");
  v1::OpenSessionResponse o;
  grpc::Status s = st.stub->OpenSession(&c2, open, &o);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "robot_id"));
  grpc::ClientContext c3;
  v1::WatchSessionRequest w;
  w.set_session_id("nope");
  auto reader = st.stub->WatchSession(&c3, w);
  v1::SessionEvent e;
  EXPECT_FALSE(reader->Read(&e));
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
}

}  // namespace
}  // namespace kinemo::coordinator
