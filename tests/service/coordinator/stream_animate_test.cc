// StreamAnimate over the real services: the prosody service on real speech,
// a remapped CRF the inference service trained, a controller the planner
// built from it (gc_models.h); the coordinator reaches them through
// in-process channels, as in the all-in-one, and is served on loopback TCP.
// Behaviour only (timing is measured by `kinemo bench e2e`): the audio clock
// drives the frames, through a long pause too; frames are gap-free and
// strictly increasing; visemes and the summary come after the last frames;
// bad chunks are refused naming the field.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <set>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "common/server/service_host.h"
#include "common/testing/process.h"
#include "kinemo/inference/v1/options.pb.h"
#include "kinemo/planner/v1/options.pb.h"
#include "kinemo/prosody/v1/options.pb.h"
#include "services/coordinator/client/live_client.h"
#include "services/coordinator/coordinator_service.h"
#include "tests/service/coordinator/live_stack.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
const std::string kSpeech = kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";

// A coordinator over the live stack (in-process channels) on loopback TCP.
struct Coordinator {
  std::shared_ptr<CoordinatorServiceImpl> service;
  std::unique_ptr<server::ServiceHost> host;
  std::unique_ptr<v1::CoordinatorService::Stub> stub;
  explicit Coordinator(v1::CoordinatorOptions o = {}) {
    auto channel = LiveStack::Get().services->InProcessChannel();
    o.mutable_animate()->mutable_models()->set_inference_model_id("crf");
    o.mutable_animate()->mutable_models()->set_controller_id("ctrl");
    auto c = CoordinatorServiceImpl::Create(o, {channel, channel, channel, nullptr, nullptr});
    EXPECT_TRUE(c.ok()) << c.status();
    service = *c;
    host = Host({{service, v1::CoordinatorService::service_full_name()}});
    stub = v1::CoordinatorService::NewStub(
        grpc::CreateChannel(host->address(), grpc::InsecureChannelCredentials()));
  }
  ~Coordinator() {
    host->Shutdown();
    service->Stop();
  }
};

// Real speech, 3 s of digital silence, real speech (16 kHz mono floats).
std::vector<float> SpeechPauseSpeech(int* rate_hz) {
  auto a = audio::DecodeAudioFile(kSpeech);
  auto b = audio::DecodeAudioFile(kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav");
  EXPECT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->sample_rate_hz, b->sample_rate_hz);
  *rate_hz = a->sample_rate_hz;
  std::vector<float> out = a->samples;
  out.resize(out.size() + static_cast<size_t>(3 * a->sample_rate_hz), 0.0f);
  out.insert(out.end(), b->samples.begin(), b->samples.end());
  return out;
}

v1::StreamAnimateRequest Config(int rate_hz, bool visemes) {
  v1::StreamAnimateRequest r;
  auto* c = r.mutable_config();
  c->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  c->mutable_format()->set_sample_rate_hz(static_cast<uint32_t>(rate_hz));
  c->mutable_format()->set_channels(1);
  c->set_visemes(visemes);
  c->set_request_id("live-test");
  return r;
}

v1::StreamAnimateRequest Chunk(const std::vector<float>& samples, size_t first, size_t n, uint64_t seq,
                               int rate_hz) {
  v1::StreamAnimateRequest q;
  q.mutable_chunk()->set_sequence_number(seq);
  q.mutable_chunk()->set_start_time_s(static_cast<double>(first) / rate_hz);
  q.mutable_chunk()->set_data(reinterpret_cast<const char*>(samples.data() + first), n * sizeof(float));
  return q;
}

class StreamAnimateLive : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!LiveStack::Get().error.empty()) FAIL() << "live stack: " << LiveStack::Get().error;
  }
};

// After every 20 ms chunk, the frames up to the audio sent arrive before the
// next chunk is sent (lockstep with a deadline: a server that held frames
// back until a syllable ended would fail here, in the 3 s pause at the
// latest). Then the end: last frames, visemes, summary.
TEST_F(StreamAnimateLive, TheAudioClockDrivesTheFramesThroughAPause) {
  Coordinator co;
  int rate = 0;
  const std::vector<float> audio = SpeechPauseSpeech(&rate);
  const bool visemes = LiveStack::Get().prosody->recognizer() != nullptr;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::minutes(3));
  auto stream = co.stub->StreamAnimate(&ctx);
  ASSERT_TRUE(stream->Write(Config(rate, visemes)));
  v1::StreamAnimateResponse r;
  ASSERT_TRUE(stream->Read(&r)) << stream->Finish().error_message();
  ASSERT_TRUE(r.has_header());
  const double dt = r.header().frame_time_s();
  ASSERT_GT(dt, 0.0);
  const int joints = r.header().skeleton().joints_size();
  EXPECT_GT(joints, 10);

  std::vector<double> frame_times;
  double last_audio_time_s = 0;
  auto take = [&](const v1::StreamAnimateResponse& m, double sent_s, uint64_t seq) {
    EXPECT_FALSE(m.has_visemes() || m.has_summary()) << "before the client half-closed";
    EXPECT_LE(m.last_chunk_sequence(), seq);
    if (!m.has_frames()) return;
    ASSERT_GT(m.frames().frames_size(), 0);
    for (const auto& f : m.frames().frames()) {
      EXPECT_EQ(f.values_size(), joints * 6);
      frame_times.push_back(f.time_s());
    }
    // audio_time_s: the media time the frames sent reach, within the audio sent.
    EXPECT_GE(m.audio_time_s(), frame_times.back());
    EXPECT_LE(m.audio_time_s(), sent_s + 1e-9);
    EXPECT_GE(m.audio_time_s(), last_audio_time_s);
    last_audio_time_s = m.audio_time_s();
  };
  const size_t n = static_cast<size_t>(rate / 50);
  uint64_t seq = 0;
  for (size_t i = 0; i < audio.size(); i += n, ++seq) {
    const size_t m = std::min(n, audio.size() - i);
    ASSERT_TRUE(stream->Write(Chunk(audio, i, m, seq, rate)));
    const double sent_s = static_cast<double>(i + m) / rate;
    const size_t want = static_cast<size_t>(std::ceil(sent_s / dt - 1e-3));
    while (frame_times.size() < want) {
      ASSERT_TRUE(stream->Read(&r)) << "no frames for " << sent_s << " s of audio: " << stream->Finish().error_message();
      take(r, sent_s, seq);
    }
    ASSERT_EQ(frame_times.size(), want) << "frames past the audio sent at " << sent_s << " s";
  }
  ASSERT_TRUE(stream->WritesDone());
  const double audio_s = static_cast<double>(audio.size()) / rate;
  std::vector<std::string> tail;  // what came after the client half-closed
  v1::StreamAnimateSummary summary;
  v1::StreamAnimateResponse end;
  while (stream->Read(&end)) {
    if (end.has_frames()) tail.push_back("frames");
    if (end.has_visemes()) {
      tail.push_back("visemes");
      EXPECT_GT(end.visemes().frames_size(), 0);
      EXPECT_GT(end.visemes().categories_size(), 0);
    }
    if (end.has_summary()) {
      tail.push_back("summary");
      summary = end.summary();
    }
  }
  const grpc::Status s = stream->Finish();
  ASSERT_TRUE(s.ok()) << s.error_message();
  // Frames at every frame time, strictly increasing, none missing, covering
  // the whole audio and no more.
  ASSERT_EQ(frame_times.size(), static_cast<size_t>(std::ceil(audio_s / dt - 1e-3)));
  for (size_t k = 0; k < frame_times.size(); ++k) ASSERT_NEAR(frame_times[k], static_cast<double>(k) * dt, 1e-9);
  // Nothing but visemes and the summary after the last chunk's frames.
  std::vector<std::string> want_tail = {"summary"};
  if (visemes) want_tail.insert(want_tail.begin(), "visemes");
  EXPECT_EQ(tail, want_tail);
  EXPECT_NEAR(summary.audio_s(), audio_s, 1e-6);
  EXPECT_EQ(summary.chunks(), seq);
  EXPECT_EQ(summary.frames(), frame_times.size());
  EXPECT_GT(summary.syllables(), 10u);
  EXPECT_GE(summary.pauses(), 1u);  // the 3 s of silence at least
  EXPECT_GT(summary.beliefs(), summary.syllables());
  EXPECT_GT(summary.decisions(), 3u);
  if (!visemes) GTEST_SKIP() << "CMU Sphinx models are not installed: visemes not checked";
}

// A client that sends as fast as it can gets the same frames (the server
// holds it to the pipeline's pace), read on another thread.
TEST_F(StreamAnimateLive, AsFastAsPossibleGivesTheSameGapFreeFrames) {
  Coordinator co;
  auto decoded = audio::DecodeAudioFile(kSpeech);
  ASSERT_TRUE(decoded.ok());
  const int rate = decoded->sample_rate_hz;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::minutes(2));
  auto stream = co.stub->StreamAnimate(&ctx);
  ASSERT_TRUE(stream->Write(Config(rate, false)));
  std::thread writer([&] {
    const size_t n = static_cast<size_t>(rate / 50);
    uint64_t seq = 0;
    for (size_t i = 0; i < decoded->samples.size(); i += n, ++seq) {
      if (!stream->Write(Chunk(decoded->samples, i, std::min(n, decoded->samples.size() - i), seq, rate))) return;
    }
    stream->WritesDone();
  });
  double dt = 0;
  std::vector<double> times;
  v1::StreamAnimateResponse r;
  while (stream->Read(&r)) {
    if (r.has_header()) dt = r.header().frame_time_s();
    for (const auto& f : r.frames().frames()) times.push_back(f.time_s());
  }
  writer.join();
  const grpc::Status s = stream->Finish();
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_GT(dt, 0.0);
  ASSERT_EQ(times.size(), static_cast<size_t>(std::ceil(decoded->duration_s / dt - 1e-3)));
  for (size_t k = 1; k < times.size(); ++k) ASSERT_NEAR(times[k] - times[k - 1], dt, 1e-9);
}

// The face (docs/face.md): with a face model in the prosody service, every
// frame carries its face in the same message (so it never arrives after the
// frame), at the frame's time, with the OVR and thesis weights summing to 1;
// the mouth moves while the person talks, and rests in the digital silence.
TEST_F(StreamAnimateLive, EveryFrameCarriesItsFaceFromTheAudioSoFar) {
  Coordinator co;
  int rate = 0;
  const std::vector<float> audio = SpeechPauseSpeech(&rate);
  LiveStreamOptions o;
  o.realtime = false;
  o.config.set_request_id("face-test");
  auto r = RunLiveStream(grpc::CreateChannel(co.host->address(), grpc::InsecureChannelCredentials()), audio, rate, o);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_GT(r->frames.size(), 100u);
  EXPECT_EQ(r->face_frames, r->frames.size());
  std::set<int> visemes;
  int silent_at_rest = 0, silent = 0;
  // Inside the digital silence: the last 0.3 s of audio before the frame all zeros.
  auto in_silence = [&](double t) {
    const long end = static_cast<long>(t * rate), begin = end - static_cast<long>(0.3 * rate);
    if (begin < 0) return false;
    for (long i = begin; i < end && i < static_cast<long>(audio.size()); ++i) {
      if (audio[i] != 0.0f) return false;
    }
    return true;
  };
  for (const auto& f : r->frames) {
    ASSERT_TRUE(f.has_face());
    EXPECT_DOUBLE_EQ(f.face().time_s(), f.time_s());
    ASSERT_EQ(f.face().ovr_visemes_size(), 15);
    ASSERT_EQ(f.face().categories_size(), 15);
    double ovr = 0, cats = 0;
    for (float w : f.face().ovr_visemes()) ovr += w;
    for (float w : f.face().categories()) cats += w;
    EXPECT_NEAR(ovr, 1.0, 1e-3);
    EXPECT_NEAR(cats, 1.0, 1e-3);
    const auto& w = f.face().ovr_visemes();
    const int dominant = static_cast<int>(std::max_element(w.begin(), w.end()) - w.begin());
    visemes.insert(dominant);
    if (in_silence(f.time_s())) {
      ++silent;
      silent_at_rest += dominant == 0;  // sil
    }
  }
  // Speech moves the mouth through several shapes; the silence rests it.
  EXPECT_GE(visemes.size(), 4u);
  ASSERT_GT(silent, 50);
  EXPECT_GT(silent_at_rest, 0.9 * silent);
  EXPECT_GT(r->face_lag_ms.size(), 10u);
}

// Ends the stream after `messages` and returns its status.
grpc::Status StreamStatus(v1::CoordinatorService::Stub* stub, const std::vector<v1::StreamAnimateRequest>& messages) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto stream = stub->StreamAnimate(&ctx);
  for (const auto& m : messages) {
    if (!stream->Write(m)) break;
  }
  stream->WritesDone();
  v1::StreamAnimateResponse r;
  while (stream->Read(&r)) {
  }
  return stream->Finish();
}

TEST_F(StreamAnimateLive, BadChunksAreRefusedNamingTheFieldAndTheServiceStaysHealthy) {
  v1::CoordinatorOptions o;
  o.mutable_animate()->set_max_audio_s(0.5);
  Coordinator co(o);
  auto decoded = audio::DecodeAudioFile(kSpeech);
  ASSERT_TRUE(decoded.ok());
  const int rate = decoded->sample_rate_hz;
  const auto& a = decoded->samples;
  const size_t n = static_cast<size_t>(rate / 50);
  struct Case {
    std::vector<v1::StreamAnimateRequest> messages;
    std::string field;
  };
  v1::StreamAnimateRequest partial = Chunk(a, 0, n, 0, rate);
  partial.mutable_chunk()->mutable_data()->pop_back();
  v1::StreamAnimateRequest bad_rate = Config(rate, false);
  bad_rate.mutable_config()->mutable_format()->set_sample_rate_hz(1000000);
  std::vector<v1::StreamAnimateRequest> too_long = {Config(rate, false)};
  for (uint64_t k = 0; k < 30; ++k) too_long.push_back(Chunk(a, k * n, n, k, rate));  // 0.6 s > 0.5 s
  const std::vector<Case> cases = {
      {{Config(rate, false), Chunk(a, 0, n, 0, rate), Chunk(a, n, n, 2, rate)}, "chunk.sequence_number: "},
      {{Config(rate, false), partial}, "chunk.data: "},
      {{Config(rate, false), Chunk(a, 0, static_cast<size_t>(rate) + n, 0, rate)}, "chunk.data: "},
      {too_long, "chunk: "},
      {{bad_rate}, "config.format.sample_rate_hz: "},
      {{Chunk(a, 0, n, 0, rate)}, "config: "},
      {{Config(rate, false), Config(rate, false)}, "config: "},
  };
  for (const Case& c : cases) {
    const grpc::Status s = StreamStatus(co.stub.get(), c.messages);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field << " " << s.error_message();
    EXPECT_TRUE(absl::StartsWith(s.error_message(), c.field)) << s.error_message();
  }
  // Unknown models: the downstream service's answer, prefixed with its
  // name, while the client is still streaming (it does not half-close).
  for (const char* which : {"model", "controller"}) {
    v1::StreamAnimateRequest unknown = Config(rate, false);
    if (std::string(which) == "model") unknown.mutable_config()->mutable_models()->set_inference_model_id("nope");
    if (std::string(which) == "controller") unknown.mutable_config()->mutable_models()->set_controller_id("nope");
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    auto stream = co.stub->StreamAnimate(&ctx);
    ASSERT_TRUE(stream->Write(unknown));
    stream->Write(Chunk(a, 0, n, 0, rate));
    v1::StreamAnimateResponse r;
    while (stream->Read(&r)) {
    }
    const grpc::Status s = stream->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
    EXPECT_TRUE(absl::StartsWith(s.error_message(), std::string(which) == "model" ? "inference: " : "planner: "))
        << s.error_message();
  }
  grpc::Status s;
  // With visemes the audio must fit one message to the recogniser.
  {
    v1::CoordinatorOptions small;
    small.mutable_server()->set_max_message_bytes(256 << 10);  // about 3 s of 16 kHz floats
    Coordinator co_small(small);
    std::vector<v1::StreamAnimateRequest> all = {Config(rate, true)};
    for (uint64_t k = 0; (k + 1) * n <= a.size(); ++k) all.push_back(Chunk(a, k * n, n, k, rate));
    const grpc::Status vs = StreamStatus(co_small.stub.get(), all);
    EXPECT_EQ(vs.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << vs.error_message();
    EXPECT_TRUE(absl::StartsWith(vs.error_message(), "chunk: with config.visemes")) << vs.error_message();
  }
  // And a good stream still runs.
  std::vector<v1::StreamAnimateRequest> good = {Config(rate, false)};
  for (uint64_t k = 0; k < 20; ++k) good.push_back(Chunk(a, k * n, n, k, rate));
  s = StreamStatus(co.stub.get(), good);
  EXPECT_TRUE(s.ok()) << s.error_message();
}

// Admission: with animate.max_concurrent_streams 2, three real-time streams
// opened at once: one is refused at once with RESOURCE_EXHAUSTED naming the
// option (it gets no frame), the two admitted run to their end with every
// frame of their audio; once they are over, their slots are free again.
TEST_F(StreamAnimateLive, PastMaxConcurrentStreamsNewStreamsAreRefusedAndAdmittedOnesRun) {
  v1::CoordinatorOptions o;
  o.mutable_animate()->set_max_concurrent_streams(2);
  Coordinator co(o);
  auto decoded = audio::DecodeAudioFile(kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav");
  ASSERT_TRUE(decoded.ok());
  auto channel = grpc::CreateChannel(co.host->address(), grpc::InsecureChannelCredentials());
  LiveStreamOptions lo;
  lo.realtime = true;
  lo.keep_frames = false;
  auto results = RunLiveStreams(channel, decoded->samples, decoded->sample_rate_hz, lo, 3);
  ASSERT_EQ(results.size(), 3u);
  int refused = 0, admitted = 0;
  for (const auto& r : results) {
    if (!r.ok()) {
      ++refused;
      EXPECT_EQ(r.status().code(), absl::StatusCode::kResourceExhausted) << r.status();
      EXPECT_TRUE(absl::StrContains(r.status().message(), "animate.max_concurrent_streams")) << r.status();
      continue;
    }
    ++admitted;
    const double dt = r->header.frame_time_s();
    ASSERT_GT(dt, 0.0);
    // Every frame of the audio, all of them counted by the server too.
    EXPECT_EQ(r->frame_count, static_cast<uint64_t>(std::ceil(decoded->duration_s / dt - 1e-3)));
    EXPECT_EQ(r->summary.frames(), r->frame_count);
    EXPECT_EQ(r->summary.chunks(), r->chunks);
  }
  EXPECT_EQ(refused, 1);
  EXPECT_EQ(admitted, 2);
  // The slots are free again: two new streams are admitted.
  lo.realtime = false;
  for (const auto& r : RunLiveStreams(channel, decoded->samples, decoded->sample_rate_hz, lo, 2)) {
    EXPECT_TRUE(r.ok()) << r.status();
  }
}

}  // namespace
}  // namespace kinemo::coordinator
