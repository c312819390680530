// The planner's Gesture Controller RPCs over real gRPC: LoadLibrary (segment
// counts), BuildController (progress stream, stored info), Synthesize (BVH
// of the requested length), Control (header, frames at the pace of the
// beliefs, decisions, keyword served; frames at the pace of the audio clock
// with late beliefs; bounded media time) and the error mapping.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <thread>
#include <grpcpp/grpcpp.h>

#include "common/motion/bvh.h"
#include "common/server/service_host.h"
#include "services/planner/rpc/planner_service.h"
#include "tests/unit/planner_controller/test_util.h"

namespace kinemo::planner {
namespace {

namespace ctl = controller;

// A planner on the test library, served on a loopback port.
void StartPlanner(v1::PlannerOptions o, std::unique_ptr<server::ServiceHost>* host,
                  std::unique_ptr<v1::PlannerService::Stub>* stub,
                  std::shared_ptr<PlannerServiceImpl>* service = nullptr) {
  o.set_library_root(ctl::testing::DataDir());
  auto svc = PlannerServiceImpl::Create(o);
  ASSERT_TRUE(svc.ok()) << svc.status();
  if (service != nullptr) *service = *svc;
  common::v1::ServerOptions so;
  so.set_host("127.0.0.1");
  so.set_port(0);
  so.set_shutdown_grace_s(1);
  auto h = server::ServiceHost::Start(so, "planner-test", {{*svc, v1::PlannerService::service_full_name()}});
  ASSERT_TRUE(h.ok()) << h.status();
  *host = *std::move(h);
  // Over loopback TCP: the in-process transport hands a message over only
  // when the peer reads it, which a client that writes several messages
  // before reading (as the Control tests below do) would deadlock.
  *stub = v1::PlannerService::NewStub(grpc::CreateChannel((*host)->address(), grpc::InsecureChannelCredentials()));
}

class ControllerServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    v1::PlannerOptions o;
    o.set_max_output_s(30);
    ASSERT_NO_FATAL_FAILURE(StartPlanner(o, &host_, &stub_));
    model_ = ctl::testing::FitStateModel(*ctl::testing::TestLibrary(), 4);
  }
  void TearDown() override { host_->Shutdown(); }

  void LoadLib() {
    grpc::ClientContext ctx;
    v1::LoadLibraryRequest req;
    req.set_library_id("gestures");
    req.add_paths("manifest.json");
    v1::LoadLibraryResponse resp;
    const grpc::Status st = stub_->LoadLibrary(&ctx, req, &resp);
    ASSERT_TRUE(st.ok()) << st.error_message();
    library_ = resp.library();
  }

  v1::ControllerInfo Build(const std::string& id, grpc::Status* status, int* progress_messages) {
    grpc::ClientContext ctx;
    v1::BuildControllerRequest req;
    req.set_controller_id(id);
    req.set_library_id("gestures");
    *req.mutable_state_model() = StateModelProto();
    req.set_inference_model_id("fitted");
    auto reader = stub_->BuildController(&ctx, req);
    v1::BuildControllerResponse msg;
    v1::ControllerInfo info;
    *progress_messages = 0;
    double last_fraction = -1;
    while (reader->Read(&msg)) {
      ++*progress_messages;
      EXPECT_GE(msg.progress().fraction(), last_fraction);
      last_fraction = msg.progress().fraction();
      if (msg.has_controller()) info = msg.controller();
    }
    *status = reader->Finish();
    return info;
  }

  v1::StateModel StateModelProto() const { return ctl::testing::StateModelProto(model_); }
  std::vector<v1::BeliefStep> Beliefs(double duration_s) const {
    return ctl::testing::DriftingBeliefs(model_.num_states(), duration_s);
  }

  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::PlannerService::Stub> stub_;
  ctl::StateModel model_;
  v1::LibraryInfo library_;
};

TEST_F(ControllerServiceTest, LoadLibraryCountsSegments) {
  LoadLib();
  EXPECT_EQ(library_.clips_size(), 7);
  uint32_t sum = 0;
  for (const auto& c : library_.clips()) {
    EXPECT_GE(c.segments(), 1u) << c.name();
    sum += c.segments();
  }
  EXPECT_EQ(library_.segments(), sum);
  EXPECT_GT(sum, 3u * 7u);  // gestures have several phases
}

TEST_F(ControllerServiceTest, BuildSynthesizeControl) {
  LoadLib();
  grpc::Status st;
  int messages = 0;
  const v1::ControllerInfo info = Build("ctrl", &st, &messages);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_GE(messages, 2);
  EXPECT_EQ(info.controller_id(), "ctrl");
  EXPECT_EQ(info.version(), 1u);
  EXPECT_EQ(info.library_id(), "gestures");
  EXPECT_EQ(info.segments(), library_.segments());
  EXPECT_EQ(info.num_states(), 4u);
  EXPECT_GT(info.culled_fraction(), 0.0);
  EXPECT_GT(info.entries(), 0u);
  EXPECT_EQ(info.tones_size(), 3);
  EXPECT_NEAR(info.params().discount(), 0.9, 1e-12);

  // Building the same id again needs overwrite.
  Build("ctrl", &st, &messages);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::ALREADY_EXISTS);

  // Offline synthesis: BVH of the requested length, segments listed.
  {
    grpc::ClientContext ctx;
    v1::SynthesizeRequest req;
    req.set_controller_id("ctrl");
    for (const auto& b : Beliefs(6.0)) *req.add_beliefs() = b;
    auto* kw = req.add_keywords();
    kw->set_word("bye");
    kw->set_start_s(2.0);
    kw->set_end_s(2.4);
    kw->set_keyword(true);
    (*req.mutable_style()->mutable_tone_weights())["energetic"] = 1.0;
    v1::SynthesizeResponse resp;
    st = stub_->Synthesize(&ctx, req, &resp);
    ASSERT_TRUE(st.ok()) << st.error_message();
    auto clip = motion::ParseBvh(resp.motion().bvh(), "synth.bvh");
    ASSERT_TRUE(clip.ok()) << clip.status();
    EXPECT_EQ(clip->num_frames(), 180);
    ASSERT_GT(resp.segments_size(), 1);
    EXPECT_NEAR(resp.segments(0).start_s(), 0.0, 1e-9);
    EXPECT_NEAR(resp.segments(resp.segments_size() - 1).end_s(), 6.0, 1e-3);
    bool served = false;
    for (const auto& s : resp.segments()) served = served || (s.keyword() == "bye" && s.start_s() <= 2.9);
    EXPECT_TRUE(served);
    EXPECT_GT(resp.max_transition_angular_speed_dps(), 0.0);
  }

  // Online control: frames follow the beliefs' end times.
  {
    grpc::ClientContext ctx;
    auto stream = stub_->Control(&ctx);
    v1::ControlRequest req;
    req.mutable_config()->set_controller_id("ctrl");
    req.mutable_config()->set_emit_decisions(true);
    ASSERT_TRUE(stream->Write(req));
    v1::ControlResponse resp;
    ASSERT_TRUE(stream->Read(&resp));
    ASSERT_TRUE(resp.has_header());
    EXPECT_EQ(resp.header().skeleton().joints_size(), 22);
    EXPECT_NEAR(resp.header().frame_time_s(), 1.0 / 30, 1e-6);
    // Read on another thread while writing (the stream runs at the pace of
    // its input; nothing is buffered without a reader).
    int frames = 0, decisions = 0;
    double last_time = -1, bow_start = -1;
    std::thread reader([&] {
      v1::ControlResponse r;
      while (stream->Read(&r)) {
        if (r.has_frames()) {
          for (const auto& f : r.frames().frames()) {
            EXPECT_GT(f.time_s(), last_time);
            last_time = f.time_s();
            EXPECT_EQ(f.values_size(), 22 * 6);
            ++frames;
          }
        } else if (r.has_decision()) {
          ++decisions;
          EXPECT_GE(r.decision().decide_us(), 0.0);
          if (r.decision().next().keyword() == "bow" && bow_start < 0) bow_start = r.decision().time_s();
        }
      }
    });
    const auto beliefs = Beliefs(3.0);
    for (size_t t = 0; t < beliefs.size(); ++t) {
      v1::ControlRequest r;
      *r.mutable_belief() = beliefs[t];
      ASSERT_TRUE(stream->Write(r));
      if (t == 4) {
        v1::ControlRequest k;
        k.mutable_keyword()->set_word("bow");
        k.mutable_keyword()->set_end_s(1.25);
        ASSERT_TRUE(stream->Write(k));
      }
    }
    ASSERT_TRUE(stream->WritesDone());
    reader.join();
    ASSERT_TRUE(stream->Finish().ok());
    EXPECT_EQ(frames, 90);  // 3 s at 30 fps
    EXPECT_GT(decisions, 3);
    EXPECT_GE(bow_start, 1.25);
    EXPECT_LE(bow_start, 1.25 + 0.5);
  }
}

TEST_F(ControllerServiceTest, Errors) {
  LoadLib();
  {
    grpc::ClientContext ctx;
    v1::SynthesizeRequest req;
    req.set_controller_id("nope");
    v1::SynthesizeResponse resp;
    EXPECT_EQ(stub_->Synthesize(&ctx, req, &resp).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  grpc::Status st;
  int messages = 0;
  {
    grpc::ClientContext ctx;
    v1::BuildControllerRequest req;
    req.set_controller_id("bad");
    req.set_library_id("gestures");
    *req.mutable_state_model() = StateModelProto();
    req.mutable_state_model()->mutable_states(0)->add_mean(1.0);  // 7 values
    auto reader = stub_->BuildController(&ctx, req);
    v1::BuildControllerResponse msg;
    while (reader->Read(&msg)) {
    }
    st = reader->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(st.error_message().find("states[0]"), std::string::npos) << st.error_message();
  }
  Build("ok", &st, &messages);
  ASSERT_TRUE(st.ok());
  {
    grpc::ClientContext ctx;
    v1::SynthesizeRequest req;
    req.set_controller_id("ok");
    auto b = Beliefs(1.0);
    b[1].add_probabilities(0.0);  // 5 values for 4 states
    for (const auto& x : b) *req.add_beliefs() = x;
    v1::SynthesizeResponse resp;
    st = stub_->Synthesize(&ctx, req, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(st.error_message().find("beliefs[1]"), std::string::npos) << st.error_message();
  }
  {
    grpc::ClientContext ctx;
    auto stream = stub_->Control(&ctx);
    v1::ControlRequest req;
    req.mutable_config()->set_controller_id("ok");
    (*req.mutable_config()->mutable_style()->mutable_tone_weights())["grumpy"] = 1;
    ASSERT_TRUE(stream->Write(req));
    stream->WritesDone();
    v1::ControlResponse resp;
    while (stream->Read(&resp)) {
    }
    st = stream->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(st.error_message().find("style"), std::string::npos);
  }
  // Gesture emphasis: in range it is accepted (config and a style change),
  // out of range or NaN refused naming style.gesture_emphasis.
  for (double bad : {1.5, -1.01, std::nan("")}) {
    grpc::ClientContext ctx;
    auto stream = stub_->Control(&ctx);
    v1::ControlRequest req;
    req.mutable_config()->set_controller_id("ok");
    req.mutable_config()->mutable_style()->set_gesture_emphasis(0.8);
    ASSERT_TRUE(stream->Write(req));
    v1::ControlResponse resp;
    ASSERT_TRUE(stream->Read(&resp));
    EXPECT_TRUE(resp.has_header());
    v1::ControlRequest style;
    (*style.mutable_style()->mutable_tone_weights())["neutral"] = 1;
    style.mutable_style()->set_gesture_emphasis(bad);
    stream->Write(style);
    stream->WritesDone();
    while (stream->Read(&resp)) {
    }
    st = stream->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << bad;
    EXPECT_NE(st.error_message().find("style.gesture_emphasis"), std::string::npos) << st.error_message();
  }
  {
    grpc::ClientContext ctx;
    v1::SynthesizeRequest req;
    req.set_controller_id("ok");
    for (const auto& x : Beliefs(1.0)) *req.add_beliefs() = x;
    req.mutable_style()->set_gesture_emphasis(-3);
    v1::SynthesizeResponse resp;
    st = stub_->Synthesize(&ctx, req, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(st.error_message().find("style.gesture_emphasis"), std::string::npos) << st.error_message();
  }
}


// What one live Control stream produced.
struct LiveRun {
  double frame_time_s = 0;
  std::vector<double> frame_times;
  std::vector<std::pair<double, uint32_t>> decisions;  // (time, segment)
  double first_belief_s = -1;                          // media time when the first belief was sent
};

// Media time advances in 20 ms steps (the audio clock) to `duration_s`; with
// `late_by_s`, each 0.25 s belief is sent once media time is that far past
// its end (as prosody and inference lag the audio). After every advance the
// frames up to it must arrive before anything else is sent (lockstep, with a
// deadline: a planner that held frames back would fail here).
LiveRun RunLive(v1::PlannerService::Stub* stub, const std::vector<v1::BeliefStep>& beliefs,
                std::optional<double> late_by_s, double duration_s) {
  LiveRun out;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto stream = stub->Control(&ctx);
  v1::ControlRequest req;
  req.mutable_config()->set_controller_id("ctrl");
  req.mutable_config()->set_emit_decisions(true);
  EXPECT_TRUE(stream->Write(req));
  v1::ControlResponse resp;
  EXPECT_TRUE(stream->Read(&resp));
  EXPECT_TRUE(resp.has_header());
  const double dt = out.frame_time_s = resp.header().frame_time_s();
  size_t next_belief = 0;
  for (int i = 1; i * 0.02 <= duration_s + 1e-9; ++i) {
    const double media_s = i * 0.02;
    while (late_by_s && next_belief < beliefs.size() && beliefs[next_belief].end_s() + *late_by_s <= media_s) {
      v1::ControlRequest b;
      *b.mutable_belief() = beliefs[next_belief++];
      if (out.first_belief_s < 0) out.first_belief_s = media_s;
      EXPECT_TRUE(stream->Write(b));
    }
    v1::ControlRequest a;
    a.set_advance_to_s(media_s);
    EXPECT_TRUE(stream->Write(a));
    const size_t want = static_cast<size_t>(std::ceil(media_s / dt - 1e-3));
    while (out.frame_times.size() < want) {
      if (!stream->Read(&resp)) {
        ADD_FAILURE() << "stream ended at " << media_s << " s: " << stream->Finish().error_message();
        return out;
      }
      for (const auto& f : resp.frames().frames()) out.frame_times.push_back(f.time_s());
      if (resp.has_decision()) out.decisions.emplace_back(resp.decision().time_s(), resp.decision().next().segment_index());
    }
  }
  EXPECT_TRUE(stream->WritesDone());
  while (stream->Read(&resp)) {
    for (const auto& f : resp.frames().frames()) out.frame_times.push_back(f.time_s());
  }
  EXPECT_TRUE(stream->Finish().ok());
  return out;
}

TEST_F(ControllerServiceTest, ControlFollowsTheAudioClockAndLateBeliefsChangeLaterDecisions) {
  LoadLib();
  grpc::Status st;
  int messages = 0;
  Build("ctrl", &st, &messages);
  ASSERT_TRUE(st.ok()) << st.error_message();
  // Beliefs that each put most weight on one state, in turn.
  std::vector<v1::BeliefStep> beliefs;
  for (int t = 0; t * 0.25 < 8.0; ++t) {
    v1::BeliefStep b;
    b.set_step(static_cast<uint64_t>(t));
    b.set_start_s(t * 0.25);
    b.set_end_s(t * 0.25 + 0.25);
    for (int i = 0; i < 4; ++i) b.add_probabilities(i == (t / 4) % 4 ? 0.85 : 0.05);
    beliefs.push_back(b);
  }
  const LiveRun silent = RunLive(stub_.get(), beliefs, std::nullopt, 8.0);
  const LiveRun late = RunLive(stub_.get(), beliefs, 0.3, 8.0);
  // Frames at every frame time from 0 to 8 s (30 fps), once each, in both
  // runs: the audio clock drives them, beliefs or not.
  for (const LiveRun* run : {&silent, &late}) {
    ASSERT_EQ(run->frame_times.size(), 240u);
    for (size_t k = 0; k < run->frame_times.size(); ++k)
      ASSERT_NEAR(run->frame_times[k], static_cast<double>(k) * run->frame_time_s, 1e-9);
  }
  // Decisions before the first belief are the same; the late beliefs change
  // the ones after it.
  ASSERT_GT(late.first_belief_s, 0.5);
  ASSERT_GT(silent.decisions.size(), 3u);
  size_t same_prefix = 0;
  while (same_prefix < std::min(silent.decisions.size(), late.decisions.size()) &&
         silent.decisions[same_prefix] == late.decisions[same_prefix]) {
    ++same_prefix;
  }
  for (size_t k = 0; k < late.decisions.size() && late.decisions[k].first < late.first_belief_s; ++k) {
    EXPECT_LT(k, same_prefix) << "decision " << k << " at " << late.decisions[k].first << " s changed before any belief";
  }
  EXPECT_NE(silent.decisions, late.decisions);
}

// Writes `bad` after the config and returns the status the stream ends with.
grpc::Status ControlRefuses(v1::PlannerService::Stub* stub, const std::vector<v1::ControlRequest>& before,
                            const v1::ControlRequest& bad, int* frames) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  auto stream = stub->Control(&ctx);
  v1::ControlRequest req;
  req.mutable_config()->set_controller_id("ok");
  EXPECT_TRUE(stream->Write(req));
  for (const auto& r : before) EXPECT_TRUE(stream->Write(r));
  stream->Write(bad);
  stream->WritesDone();
  v1::ControlResponse resp;
  *frames = 0;
  while (stream->Read(&resp)) *frames += resp.frames().frames_size();
  return stream->Finish();
}

TEST_F(ControllerServiceTest, ControlBoundsMediaTimeAndStaysHealthy) {
  LoadLib();
  grpc::Status st;
  int messages = 0;
  Build("ok", &st, &messages);
  ASSERT_TRUE(st.ok());
  auto advance = [](double t) {
    v1::ControlRequest r;
    r.set_advance_to_s(t);
    return r;
  };
  int frames = 0;
  // The request of issue 16: advance_to_s 1e9 once allocated without bound.
  st = ControlRefuses(stub_.get(), {}, advance(1e9), &frames);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message().rfind("advance_to_s: ", 0), 0u) << st.error_message();
  EXPECT_EQ(frames, 0);
  // More than 10 s in one message.
  st = ControlRefuses(stub_.get(), {advance(5)}, advance(15.5), &frames);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("at most 10 s per message"), std::string::npos) << st.error_message();
  EXPECT_EQ(frames, 150);  // the 5 s before it
  // Past max_output_s (30 s here), in steps.
  st = ControlRefuses(stub_.get(), {advance(10), advance(20), advance(30)}, advance(30.5), &frames);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("max_output_s"), std::string::npos) << st.error_message();
  EXPECT_EQ(frames, 900);
  st = ControlRefuses(stub_.get(), {}, advance(std::nan("")), &frames);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message().rfind("advance_to_s: ", 0), 0u) << st.error_message();
  // A belief cannot jump media time either.
  v1::ControlRequest b;
  b.mutable_belief()->set_start_s(0);
  b.mutable_belief()->set_end_s(1e9);
  for (int i = 0; i < 4; ++i) b.mutable_belief()->add_probabilities(0.25);
  st = ControlRefuses(stub_.get(), {}, b, &frames);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message().rfind("belief.end_s: ", 0), 0u) << st.error_message();
  // The service still serves streams.
  st = ControlRefuses(stub_.get(), {advance(2)}, advance(3), &frames);
  EXPECT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(frames, 90);
}

// Admission of Control streams (max_concurrent_streams): a refused stream
// holds no slot, and a stream's slot is free by the time its client hears
// its end (so the client's next stream is admitted at once).
TEST(ControlAdmission, RefusedStreamsHoldNoSlotAndAnEndedStreamFreesItsSlotBeforeItsStatus) {
  v1::PlannerOptions o;
  o.set_max_concurrent_streams(1);
  std::unique_ptr<server::ServiceHost> host;
  std::unique_ptr<v1::PlannerService::Stub> stub;
  std::shared_ptr<PlannerServiceImpl> svc;
  ASSERT_NO_FATAL_FAILURE(StartPlanner(o, &host, &stub, &svc));
  // A stream that sends nothing and half-closes: OK, or the refusal.
  auto empty_stream = [&] {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    auto stream = stub->Control(&ctx);
    stream->WritesDone();
    v1::ControlResponse r;
    while (stream->Read(&r)) {
    }
    return stream->Finish();
  };
  for (int round = 0; round < 3; ++round) {
    // This stream holds the only slot until it half-closes.
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    auto held = stub->Control(&ctx);
    for (int i = 0; i < 3; ++i) {
      // Wait until the server counts the held stream (the call reaches it
      // asynchronously); every refusal must leave the count alone.
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
      while (svc->control_streams.load() < 1 && std::chrono::steady_clock::now() < until) {
        std::this_thread::yield();
      }
      const grpc::Status refused = empty_stream();
      EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << refused.error_message();
      EXPECT_NE(refused.error_message().find("max_concurrent_streams"), std::string::npos);
      EXPECT_EQ(svc->control_streams.load(), 1);
    }
    held->WritesDone();
    v1::ControlResponse r;
    while (held->Read(&r)) {
    }
    EXPECT_TRUE(held->Finish().ok());
    // Heard its end: the slot is free.
    EXPECT_EQ(svc->control_streams.load(), 0);
    const grpc::Status next = empty_stream();
    EXPECT_TRUE(next.ok()) << next.error_message();
  }
  host->Shutdown();
}

}  // namespace
}  // namespace kinemo::planner
