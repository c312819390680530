// AnimateChunked over the real prosody, inference and planner services
// (live_stack.h: a model the inference service trained, a controller and a
// gesture graph the planner built), every server and channel limited to
// 1 MiB messages, so that a minute of real speech is larger than a message
// on every hop: the recording (3.8 MB of 16 kHz F32LE) on the way in, its
// motion (about 3 MB of BVH) on the way out. The motion is the one Animate
// makes of the same samples; bad chunks are refused naming the field; a
// caller that cancels ends the call. The face is the one Animate answers,
// one frame per motion frame, in pieces after their motion.
#include <algorithm>
#include <chrono>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "common/motion/bvh.h"
#include "services/coordinator/coordinator_service.h"
#include "tests/service/coordinator/live_stack.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
using namespace std::chrono_literals;

constexpr std::uint32_t kLimit = 1 << 20;
const std::string kClip = kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";

// A coordinator over the 1 MiB stack, itself limited to 1 MiB.
struct SmallCoordinator {
  std::shared_ptr<CoordinatorServiceImpl> service;
  std::unique_ptr<server::ServiceHost> host;
  std::unique_ptr<v1::CoordinatorService::Stub> stub;
  explicit SmallCoordinator(v1::CoordinatorOptions o = {}) {
    auto channel = LiveStack::SmallMessages().services->InProcessChannel();
    o.mutable_server()->set_max_message_bytes(kLimit);
    o.mutable_animate()->mutable_models()->set_inference_model_id("crf");
    o.mutable_animate()->mutable_models()->set_controller_id("ctrl");
    o.mutable_animate()->mutable_models()->set_gesture_graph_id("graph");
    auto c = CoordinatorServiceImpl::Create(o, {channel, channel, channel, nullptr, nullptr});
    EXPECT_TRUE(c.ok()) << c.status();
    service = *c;
    host = Host({{service, v1::CoordinatorService::service_full_name()}}, kLimit);
    stub = v1::CoordinatorService::NewStub(grpc::CreateCustomChannel(
        host->address(), grpc::InsecureChannelCredentials(), server::ChannelArgsForMessageLimit(kLimit)));
  }
  ~SmallCoordinator() {
    host->Shutdown();
    service->Stop();
  }
};

class AnimateChunked : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!LiveStack::SmallMessages().error.empty()) FAIL() << "live stack: " << LiveStack::SmallMessages().error;
  }
};

std::vector<float> Decode(const std::string& path) {
  auto a = audio::DecodeAudioFile(path);
  EXPECT_TRUE(a.ok() && a->sample_rate_hz == 16000) << path;
  return a.ok() ? a->samples : std::vector<float>();
}

// A minute of real speech: the LibriVox clips with half-second pauses.
std::vector<float> SpeechMinute() {
  std::vector<float> out;
  while (out.size() < 60 * 16000) {
    for (const char* id : {"0870", "0880", "0890", "0920", "0930"}) {
      const auto clip = Decode(kData + "/speech/sense_and_sensibility_01_austen_64kb-" + id + ".wav");
      out.insert(out.end(), clip.begin(), clip.end());
      out.resize(out.size() + 8000, 0.0f);
    }
  }
  out.resize(60 * 16000);
  return out;
}

// Waits (up to 10 s) until the live stack's prosody service runs no chunked
// analysis.
bool NoChunkedAnalysis() {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (LiveStack::SmallMessages().prosody->active_chunked().load() > 0) {
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

struct Chunked {
  grpc::Status status;
  std::string bvh;
  std::vector<std::size_t> piece_bytes;
  std::vector<v1::AnimateStage> stages;
  planner::v1::VisemeTrack visemes;
  common::v1::FaceTrack face;
  std::vector<std::size_t> face_piece_bytes;
  // Motion frames (BVH lines or clip frames) received before each face
  // piece, and the face frames received before it.
  std::vector<std::pair<std::int64_t, std::int64_t>> face_after;
  std::int64_t clip_frames = 0;
  std::vector<common::v1::FaceFrame> clip_faces;  // MotionFrame.face of the clip frames
  v1::AnimateResponse result;
};

// Frame lines of BVH text received so far (after its Frame Time line).
std::int64_t BvhFrameLines(const std::string& bvh) {
  const auto at = bvh.find("Frame Time:");
  if (at == std::string::npos) return 0;
  const auto start = bvh.find('\n', at);
  return start == std::string::npos ? 0 : std::count(bvh.begin() + static_cast<std::ptrdiff_t>(start) + 1, bvh.end(), '\n');
}

// AnimateChunked of 16 kHz mono samples in chunks of `chunk` samples; the
// first `cancel_after` chunks only when it is > 0 (then the call is
// cancelled).
Chunked RunChunked(v1::CoordinatorService::Stub* stub, const std::vector<float>& samples, v1::AnimateRequest request,
                   std::size_t chunk = 16000, std::size_t cancel_after = 0) {
  Chunked out;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 300s);
  auto stream = stub->AnimateChunked(&ctx);
  v1::AnimateChunkedRequest config;
  auto* format = request.mutable_audio()->mutable_format();
  format->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  format->set_sample_rate_hz(16000);
  format->set_channels(1);
  *config.mutable_config()->mutable_request() = request;
  config.mutable_config()->set_expected_duration_s(static_cast<double>(samples.size()) / 16000);
  bool open = stream->Write(config);
  std::uint64_t seq = 0;
  for (std::size_t i = 0; open && i < samples.size(); i += chunk) {
    if (cancel_after > 0 && seq == cancel_after) {
      ctx.TryCancel();
      break;
    }
    v1::AnimateChunkedRequest q;
    q.mutable_chunk()->set_sequence_number(seq++);
    q.mutable_chunk()->set_data(reinterpret_cast<const char*>(samples.data() + i),
                                std::min(chunk, samples.size() - i) * sizeof(float));
    open = stream->Write(q);
  }
  if (open && cancel_after == 0) stream->WritesDone();
  v1::AnimateChunkedResponse r;
  while (stream->Read(&r)) {
    if (r.has_progress()) out.stages.push_back(r.progress().stage());
    if (r.has_motion()) {
      out.bvh += r.motion().bvh();
      out.clip_frames += r.motion().frames().frames_size();
      for (const auto& f : r.motion().frames().frames()) out.clip_faces.push_back(f.face());
      out.piece_bytes.push_back(r.ByteSizeLong());
    }
    if (r.has_face()) {
      out.face_after.emplace_back(out.clip_frames + BvhFrameLines(out.bvh), out.face.frames_size());
      out.face.set_frame_time_s(r.face().frame_time_s());
      for (const auto& f : r.face().frames()) *out.face.add_frames() = f;
      out.face_piece_bytes.push_back(r.ByteSizeLong());
    }
    if (r.has_visemes()) {
      if (r.visemes().categories_size() > 0) {
        out.visemes.set_frame_time_s(r.visemes().frame_time_s());
        *out.visemes.mutable_categories() = r.visemes().categories();
      }
      for (const auto& f : r.visemes().frames()) *out.visemes.add_frames() = f;
    }
    if (r.has_result()) out.result = r.result();
  }
  out.status = stream->Finish();
  return out;
}

v1::AnimateRequest Request(v1::Method method) {
  v1::AnimateRequest r;
  r.set_method(method);
  r.set_request_id("chunked-test");
  return r;
}

// The same samples give the same motion as Animate (byte for byte), the
// same prosody summary and the same report, with every method; the same
// visemes where the recogniser is installed.
TEST_F(AnimateChunked, TheMotionIsTheOneAnimateMakes) {
  SmallCoordinator co;
  const std::vector<float> samples = Decode(kClip);
  std::string file;
  {
    std::ifstream in(kClip, std::ios::binary);
    file.assign(std::istreambuf_iterator<char>(in), {});
  }
  const bool visemes = LiveStack::SmallMessages().prosody->recognizer() != nullptr;
  for (auto method : {v1::METHOD_GESTURE_CONTROLLER, v1::METHOD_GMG, v1::METHOD_BODYSPEECH}) {
    SCOPED_TRACE(v1::Method_Name(method));
    v1::AnimateRequest unary = Request(method);
    unary.set_visemes(visemes);
    unary.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
    unary.mutable_audio()->set_data(file);
    v1::AnimateResponse expected;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 120s);
    const grpc::Status s = co.stub->Animate(&ctx, unary, &expected);
    ASSERT_TRUE(s.ok()) << s.error_message();
    v1::AnimateRequest request = Request(method);
    request.set_visemes(visemes);
    const Chunked got = RunChunked(co.stub.get(), samples, request);
    ASSERT_TRUE(got.status.ok()) << got.status.error_message();
    EXPECT_EQ(got.bvh, expected.motion().bvh());
    // The face: Animate's, frame for frame (one per motion frame).
    ASSERT_GT(expected.face().frames_size(), 100);
    EXPECT_EQ(got.face.frames_size(), BvhFrameLines(got.bvh));
    EXPECT_TRUE(got.face.SerializeAsString() == expected.face().SerializeAsString())
        << got.face.frames_size() << " face frames, Animate's " << expected.face().frames_size();
    EXPECT_FALSE(got.result.has_face());
    EXPECT_EQ(got.visemes.SerializeAsString(), expected.visemes().SerializeAsString());
    if (visemes) {
      EXPECT_GT(got.visemes.frames_size(), 100);
    }
    EXPECT_EQ(got.result.prosody().SerializeAsString(), expected.prosody().SerializeAsString());
    EXPECT_EQ(got.result.segments_size(), expected.segments_size());
    EXPECT_EQ(got.result.accent_report_size(), expected.accent_report_size());
    EXPECT_EQ(got.result.method(), method);
    EXPECT_EQ(got.result.request_id(), "chunked-test");
    EXPECT_FALSE(got.result.has_motion());
  }
}

// A minute of speech is larger than a message both ways: Animate cannot
// send its motion back and says what to use instead; AnimateChunked
// animates it with every method, in pieces under the limit.
TEST_F(AnimateChunked, ARecordingLargerThanAMessageAnimatesWithEveryMethod) {
  SmallCoordinator co;
  const std::vector<float> minute = SpeechMinute();
  ASSERT_EQ(minute.size(), 60u * 16000);
  {
    // 8 kHz 16-bit: the request fits (960 kB), the GMG motion (~3 MB) does not.
    auto at8k = audio::Resample(minute, 16000, 8000);
    ASSERT_TRUE(at8k.ok());
    std::string pcm;
    for (float x : *at8k) {
      const auto v = static_cast<std::int16_t>(std::clamp(x, -1.0f, 1.0f) * 32767);
      pcm.append(reinterpret_cast<const char*>(&v), 2);
    }
    ASSERT_LT(pcm.size(), kLimit);
    v1::AnimateRequest unary = Request(v1::METHOD_GMG);
    unary.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
    unary.mutable_audio()->mutable_format()->set_sample_rate_hz(8000);
    unary.mutable_audio()->set_data(pcm);
    v1::AnimateResponse resp;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 120s);
    const grpc::Status s = co.stub->Animate(&ctx, unary, &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
    EXPECT_TRUE(absl::StrContains(s.error_message(), "animate long recordings with CoordinatorService.AnimateChunked"))
        << s.error_message();
  }
  for (auto method : {v1::METHOD_GESTURE_CONTROLLER, v1::METHOD_GMG, v1::METHOD_BODYSPEECH}) {
    SCOPED_TRACE(v1::Method_Name(method));
    const Chunked got = RunChunked(co.stub.get(), minute, Request(method));
    ASSERT_TRUE(got.status.ok()) << got.status.error_message();
    EXPECT_GT(got.bvh.size(), kLimit) << "a motion larger than a message";
    EXPECT_GT(got.piece_bytes.size(), 1u);
    for (std::size_t b : got.piece_bytes) EXPECT_LE(b, kLimit);
    auto clip = motion::ParseBvh(got.bvh, "chunked.bvh");
    ASSERT_TRUE(clip.ok()) << clip.status();
    EXPECT_NEAR(clip->duration_s(), 60.0, 0.2);
    // One face frame per motion frame, in pieces under the limit, each after
    // the motion piece whose frames it holds: never ahead of the motion.
    EXPECT_EQ(got.face.frames_size(), clip->num_frames());
    EXPECT_NEAR(got.face.frame_time_s(), clip->frame_time_s, 1e-9);
    EXPECT_GT(got.face_piece_bytes.size(), 1u);
    for (std::size_t b : got.face_piece_bytes) EXPECT_LE(b, kLimit);
    for (const auto& [motion_frames, face_frames] : got.face_after) EXPECT_LE(face_frames, motion_frames);
    for (int i = 0; i < got.face.frames_size(); i += 97) {
      EXPECT_NEAR(got.face.frames(i).time_s(), i * clip->frame_time_s, 1e-9);
      EXPECT_EQ(got.face.frames(i).ovr_visemes_size(), 15);
    }
    EXPECT_NEAR(got.result.prosody().duration_s(), 60.0, 1e-6);
    EXPECT_GT(got.result.prosody().syllables(), 100u);
    if (method == v1::METHOD_GESTURE_CONTROLLER) {
      EXPECT_EQ(got.stages, (std::vector<v1::AnimateStage>{v1::ANIMATE_STAGE_PROSODY, v1::ANIMATE_STAGE_INFERENCE,
                                                            v1::ANIMATE_STAGE_PLANNER}));
      EXPECT_GT(got.result.segments_size(), 10);
    } else {
      EXPECT_EQ(got.stages, (std::vector<v1::AnimateStage>{v1::ANIMATE_STAGE_PROSODY, v1::ANIMATE_STAGE_PLANNER}));
      EXPECT_EQ(got.result.accent_report_size(), got.result.prosody().accents_size());
    }
  }
}

// A clip (MOTION_FORMAT_CLIP): every frame carries its face, the face
// pieces hold the same frames, Animate's.
TEST_F(AnimateChunked, ClipFramesCarryTheirFace) {
  SmallCoordinator co;
  const std::vector<float> samples = Decode(kClip);
  v1::AnimateRequest request = Request(v1::METHOD_BODYSPEECH);
  request.set_format(common::v1::MOTION_FORMAT_CLIP);
  const Chunked got = RunChunked(co.stub.get(), samples, request);
  ASSERT_TRUE(got.status.ok()) << got.status.error_message();
  ASSERT_GT(got.clip_frames, 100);
  ASSERT_EQ(got.face.frames_size(), got.clip_frames);
  ASSERT_EQ(got.clip_faces.size(), static_cast<std::size_t>(got.clip_frames));
  for (std::size_t b : got.piece_bytes) EXPECT_LE(b, kLimit);
  for (int i = 0; i < got.face.frames_size(); ++i) {
    common::v1::FaceFrame a = got.face.frames(i), b = got.clip_faces[static_cast<std::size_t>(i)];
    EXPECT_NEAR(a.time_s(), b.time_s(), 1e-6);
    a.clear_time_s();
    b.clear_time_s();
    ASSERT_TRUE(a.SerializeAsString() == b.SerializeAsString()) << "frame " << i;
  }
  // Animate's face of the same samples.
  v1::AnimateRequest unary = request;
  auto* format = unary.mutable_audio()->mutable_format();
  format->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  format->set_sample_rate_hz(16000);
  unary.mutable_audio()->set_data(std::string(reinterpret_cast<const char*>(samples.data()), samples.size() * 4));
  v1::AnimateResponse expected;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 120s);
  ASSERT_TRUE(co.stub->Animate(&ctx, unary, &expected).ok());
  EXPECT_TRUE(got.face.SerializeAsString() == expected.face().SerializeAsString());
}

TEST_F(AnimateChunked, BadRequestsAreRefusedNamingTheField) {
  v1::CoordinatorOptions o;
  o.mutable_animate()->set_max_chunked_audio_s(2);
  SmallCoordinator co(o);
  const std::vector<float> samples = Decode(kClip);
  {
    // More than animate.max_chunked_audio_s.
    const Chunked got = RunChunked(co.stub.get(), samples, Request(v1::METHOD_GMG));
    EXPECT_EQ(got.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_EQ(got.status.error_message(),
              "chunk: the stream's audio would pass 2 s (animate.max_chunked_audio_s)");
  }
  const std::vector<float> second(samples.begin(), samples.begin() + 16000);
  {
    // A chunk of more than a second.
    const Chunked got = RunChunked(co.stub.get(), samples, Request(v1::METHOD_GMG), 16001);
    EXPECT_EQ(got.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(absl::StartsWith(got.status.error_message(), "chunk.data: ")) << got.status.error_message();
  }
  struct Case {
    const char* name;
    std::function<void(v1::AnimateChunkedRequest*)> edit;
    const char* prefix;
  };
  const Case cases[] = {
      {"a file", [](v1::AnimateChunkedRequest* r) {
         r->mutable_config()->mutable_request()->mutable_audio()->mutable_format()->set_encoding(
             common::v1::AUDIO_ENCODING_FILE);
       }, "config.request.audio.format.encoding: "},
      {"data in the config", [](v1::AnimateChunkedRequest* r) {
         r->mutable_config()->mutable_request()->mutable_audio()->set_data("RIFF");
       }, "config.request.audio.data: "},
      {"96 kHz and over", [](v1::AnimateChunkedRequest* r) {
         r->mutable_config()->mutable_request()->mutable_audio()->mutable_format()->set_sample_rate_hz(192000);
       }, "config.request.audio.format.sample_rate_hz: "},
      {"no graph", [](v1::AnimateChunkedRequest* r) {
         r->mutable_config()->mutable_request()->mutable_models()->set_gesture_graph_id("nope");
       }, "planner: graph_id: "},
      {"not a face model id", [](v1::AnimateChunkedRequest* r) {
         r->mutable_config()->mutable_request()->set_face_model_id("../faces");
       }, "prosody: config.request.face_model_id: '../faces' must be 1..64 characters of [a-z0-9_-]"},
      {"an unknown face model", [](v1::AnimateChunkedRequest* r) {
         r->mutable_config()->mutable_request()->set_face_model_id("nobody");
       }, "prosody: config.request.face_model_id: no face model 'nobody' in the store"},
      {"a chunk first", [](v1::AnimateChunkedRequest* r) {
         r->clear_config();
         r->mutable_chunk()->set_sequence_number(0);
       }, "config: must be the first message"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    // The coordinator cancels the prosody analysis of a refused request; the
    // prosody service frees its slot (max_concurrent_chunked: 2) when that
    // analysis has stopped, a little after the client has its error. Each
    // case starts once the last one's analyses are gone (else: "retry later").
    ASSERT_TRUE(NoChunkedAnalysis()) << "prosody analyses still running";
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 60s);
    auto stream = co.stub->AnimateChunked(&ctx);
    v1::AnimateChunkedRequest config;
    auto* req = config.mutable_config()->mutable_request();
    req->set_method(v1::METHOD_GMG);
    req->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
    req->mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
    c.edit(&config);
    bool open = stream->Write(config);
    v1::AnimateChunkedRequest q;
    q.mutable_chunk()->set_sequence_number(config.has_chunk() ? 1 : 0);
    q.mutable_chunk()->set_data(reinterpret_cast<const char*>(second.data()), second.size() * sizeof(float));
    if (open) open = stream->Write(q);
    if (open) stream->WritesDone();
    v1::AnimateChunkedResponse r;
    while (stream->Read(&r)) {
    }
    const grpc::Status s = stream->Finish();
    EXPECT_NE(s.error_code(), grpc::StatusCode::OK);
    EXPECT_TRUE(absl::StartsWith(s.error_message(), c.prefix)) << s.error_message();
  }
  {
    // Chunks out of order.
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 60s);
    auto stream = co.stub->AnimateChunked(&ctx);
    v1::AnimateChunkedRequest config;
    auto* req = config.mutable_config()->mutable_request();
    req->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
    req->mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
    stream->Write(config);
    v1::AnimateChunkedRequest q;
    q.mutable_chunk()->set_sequence_number(3);
    q.mutable_chunk()->set_data(std::string(400, '\0'));
    stream->Write(q);
    stream->WritesDone();
    v1::AnimateChunkedResponse r;
    while (stream->Read(&r)) {
    }
    const grpc::Status s = stream->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "chunk.sequence_number: 3 out of sequence")) << s.error_message();
  }
}

// Animate with a recording over animate.max_audio_s says where it goes.
TEST_F(AnimateChunked, AnimateSaysWhereLongerRecordingsGo) {
  v1::CoordinatorOptions o;
  o.mutable_animate()->set_max_audio_s(5);
  SmallCoordinator co(o);
  std::string file;
  {
    std::ifstream in(kClip, std::ios::binary);
    file.assign(std::istreambuf_iterator<char>(in), {});
  }
  v1::AnimateRequest unary = Request(v1::METHOD_GMG);
  unary.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
  unary.mutable_audio()->set_data(file);
  v1::AnimateResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 60s);
  const grpc::Status s = co.stub->Animate(&ctx, unary, &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StrContains(s.error_message(), "(animate.max_audio_s); animate longer recordings with "
                                                   "CoordinatorService.AnimateChunked"))
      << s.error_message();
  // The same recording goes through AnimateChunked.
  const Chunked got = RunChunked(co.stub.get(), Decode(kClip), Request(v1::METHOD_GMG));
  EXPECT_TRUE(got.status.ok()) << got.status.error_message();
}

// Admission: past animate.max_concurrent_chunked a call is refused at once,
// naming the option; the running one goes on.
TEST_F(AnimateChunked, CallsPastTheLimitAreRefusedAtOnce) {
  v1::CoordinatorOptions o;
  o.mutable_animate()->set_max_concurrent_chunked(1);
  SmallCoordinator co(o);
  const std::vector<float> samples = Decode(kClip);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 120s);
  auto first = co.stub->AnimateChunked(&ctx);
  v1::AnimateChunkedRequest config;
  auto* format = config.mutable_config()->mutable_request()->mutable_audio()->mutable_format();
  format->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  format->set_sample_rate_hz(16000);
  ASSERT_TRUE(first->Write(config));
  v1::AnimateChunkedRequest q;
  q.mutable_chunk()->set_sequence_number(0);
  q.mutable_chunk()->set_data(reinterpret_cast<const char*>(samples.data()), 16000 * sizeof(float));
  ASSERT_TRUE(first->Write(q));  // taken: the first call is running
  const Chunked second = RunChunked(co.stub.get(), samples, Request(v1::METHOD_GMG));
  EXPECT_EQ(second.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_TRUE(absl::StartsWith(second.status.error_message(), "animate.max_concurrent_chunked: 1 "))
      << second.status.error_message();
  first->WritesDone();
  v1::AnimateChunkedResponse r;
  bool result = false;
  while (first->Read(&r)) result = result || r.has_result();
  EXPECT_TRUE(first->Finish().ok());
  EXPECT_TRUE(result);
}

// A caller that cancels mid-upload ends the call (CANCELLED at once, not at
// the deadline), and the next call works.
TEST_F(AnimateChunked, CancellingEndsTheCall) {
  SmallCoordinator co;
  const std::vector<float> minute = SpeechMinute();
  const auto t0 = std::chrono::steady_clock::now();
  const Chunked cancelled = RunChunked(co.stub.get(), minute, Request(v1::METHOD_GESTURE_CONTROLLER), 16000, 20);
  EXPECT_EQ(cancelled.status.error_code(), grpc::StatusCode::CANCELLED) << cancelled.status.error_message();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 30s);
  const Chunked next = RunChunked(co.stub.get(), Decode(kClip), Request(v1::METHOD_GESTURE_CONTROLLER));
  EXPECT_TRUE(next.status.ok()) << next.status.error_message();
  EXPECT_FALSE(next.bvh.empty());
}

}  // namespace
}  // namespace kinemo::coordinator
