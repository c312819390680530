// The prosody gRPC service in process (ServiceHost + InProcessChannel) on
// real LibriVox speech from tests/data/speech.
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <string>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "common/testing/process.h"
#include "tests/service/coordinator/face_store.h"
#include "common/server/service_host.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "services/prosody/prosody_service.h"

namespace kinemo::prosody {
namespace {

constexpr char kClip[] = "speech/sense_and_sensibility_01_austen_64kb-0870.wav";

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class ProsodyServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    common::v1::ServerOptions server;
    server.set_host("127.0.0.1");
    server.set_port(0);
    v1::ProsodyOptions options;
    options.set_max_audio_s(60);
    options.mutable_recognizer()->set_disabled(true);
    auto service = std::make_shared<ProsodyServiceImpl>(options);
    auto host = server::ServiceHost::Start(server, "prosody",
                                           {{service, v1::ProsodyService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = *std::move(host);
    stub_ = v1::ProsodyService::NewStub(host_->InProcessChannel());
  }
  void TearDown() override { host_->Shutdown(); }

  static void SetDeadline(grpc::ClientContext* ctx, int seconds = 60) {
    ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  }

  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::ProsodyService::Stub> stub_;
};

TEST_F(ProsodyServiceTest, AnalyzeAFile) {
  v1::AnalyzeRequest request;
  request.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
  request.mutable_audio()->set_data(ReadFile(std::string(KINEMO_TEST_DATA_DIR) + "/" + kClip));
  v1::AnalyzeResponse response;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  const grpc::Status status = stub_->Analyze(&ctx, request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  const v1::ProsodyTrack& t = response.track();
  EXPECT_NEAR(t.duration_s(), 7.1, 0.05);
  EXPECT_EQ(t.analysis_rate_hz(), 16000u);
  EXPECT_EQ(t.frames_size(), 710);
  EXPECT_GT(t.syllables_size(), 15);
  EXPECT_GT(t.accents_size(), 3);
  for (const auto& a : t.accents()) {
    EXPECT_GT(a.strength(), 0);
    EXPECT_LE(a.strength(), 1);
  }
  EXPECT_FALSE(t.recognizer_ran());
  EXPECT_DOUBLE_EQ(t.params().pitch_floor_hz(), 75);
  EXPECT_FALSE(response.request_id().empty());
}

// One second of 16 kHz silence as PCM.
void Pcm(v1::AnalyzeRequest* r) {
  r->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
  r->mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
  r->mutable_audio()->set_data(std::string(32000, '\0'));
}

TEST_F(ProsodyServiceTest, RejectsBadRequestsNamingTheField) {
  struct Case {
    std::function<void(v1::AnalyzeRequest*)> make;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](v1::AnalyzeRequest*) {}, "audio.format.encoding"},
      {[](v1::AnalyzeRequest* r) {
         r->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
         r->mutable_audio()->mutable_format()->set_sample_rate_hz(4000);
         r->mutable_audio()->set_data(std::string(800, '\0'));
       },
       "audio.format.sample_rate_hz"},
      {[](v1::AnalyzeRequest* r) {
         r->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
         r->mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
         r->mutable_audio()->set_data(std::string(16001, '\0'));  // odd byte count
       },
       "audio.data"},
      {[](v1::AnalyzeRequest* r) {
         r->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
         r->mutable_audio()->mutable_format()->set_sample_rate_hz(8000);
         r->mutable_audio()->set_data(std::string(2 * 8000 * 61, '\0'));  // over max_audio_s
       },
       "audio.data"},
      {[](v1::AnalyzeRequest* r) {
         r->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
         r->mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
         r->mutable_audio()->set_data(std::string(32000, '\0'));
         r->mutable_params()->set_pitch_floor_hz(500);
         r->mutable_params()->set_pitch_ceiling_hz(400);
       },
       "params.pitch_ceiling_hz: 400 must exceed params.pitch_floor_hz"},  // the request's names, not the options'
      {[](v1::AnalyzeRequest* r) {
         Pcm(r);
         r->mutable_params()->set_pitch_floor_hz(5);
       },
       "params.pitch_floor_hz: 5 is outside 20..1000"},
      // NaN and negative values are refused, not taken for "default".
      {[](v1::AnalyzeRequest* r) {
         Pcm(r);
         r->mutable_params()->set_pitch_floor_hz(std::nan(""));
       },
       "params.pitch_floor_hz: "},
      {[](v1::AnalyzeRequest* r) {
         Pcm(r);
         r->mutable_params()->set_min_pause_s(-0.5);
       },
       "params.min_pause_s: -0.5 is not a finite number >= 0"},
      {[](v1::AnalyzeRequest* r) {
         Pcm(r);
         r->mutable_params()->set_accent_threshold(std::numeric_limits<double>::infinity());
       },
       "params.accent_threshold: "},
      {[](v1::AnalyzeRequest* r) {
         Pcm(r);
         r->mutable_recognizer()->set_keyword_threshold(-1e-10);
       },
       "recognizer.keyword_threshold: "},
      {[](v1::AnalyzeRequest* r) {
         Pcm(r);
         r->mutable_audio()->mutable_format()->set_encoding(static_cast<common::v1::AudioEncoding>(77));
       },
       "audio.format.encoding: 77 is not a defined AudioEncoding value"},
      {[](v1::AnalyzeRequest* r) {
         r->mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
         r->mutable_audio()->set_data("RIFF garbage that is not a wav file");
       },
       "audio.data"},
  };
  for (const Case& c : cases) {
    v1::AnalyzeRequest request;
    c.make(&request);
    v1::AnalyzeResponse response;
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    const grpc::Status status = stub_->Analyze(&ctx, request, &response);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field;
    EXPECT_TRUE(absl::StartsWith(status.error_message(), c.field))
        << c.field << " vs " << status.error_message();
  }
}

TEST_F(ProsodyServiceTest, RecognizerDisabledIsAFailedPrecondition) {
  v1::AnalyzeRequest request;
  request.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
  request.mutable_audio()->set_data(ReadFile(std::string(KINEMO_TEST_DATA_DIR) + "/" + kClip));
  request.mutable_recognizer()->add_keywords("power");
  v1::AnalyzeResponse response;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  EXPECT_EQ(stub_->Analyze(&ctx, request, &response).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
}

// Streams the clip's PCM (16-bit mono 16 kHz; the canonical WAV header is
// 44 bytes) in 20 ms chunks.
TEST_F(ProsodyServiceTest, StreamAnalyzeEmitsEventsAndASummary) {
  const std::string wav = ReadFile(std::string(KINEMO_TEST_DATA_DIR) + "/" + kClip);
  ASSERT_GT(wav.size(), 44u);
  const std::string pcm = wav.substr(44);
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  auto stream = stub_->StreamAnalyze(&ctx);
  v1::StreamAnalyzeRequest config;
  config.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
  config.mutable_config()->mutable_format()->set_sample_rate_hz(16000);
  ASSERT_TRUE(stream->Write(config));
  const std::size_t chunk_bytes = 640;  // 20 ms
  uint64_t seq = 0;
  for (std::size_t i = 0; i < pcm.size(); i += chunk_bytes) {
    v1::StreamAnalyzeRequest r;
    r.mutable_chunk()->set_sequence_number(seq++);
    r.mutable_chunk()->set_data(pcm.substr(i, std::min(chunk_bytes, pcm.size() - i)));
    ASSERT_TRUE(stream->Write(r));
  }
  stream->WritesDone();
  v1::StreamAnalyzeResponse response;
  int n = 0, syllables = 0, accents = 0;
  bool info_first = false, summary = false;
  while (stream->Read(&response)) {
    if (n++ == 0) info_first = response.has_info();
    if (response.has_syllable()) {
      ++syllables;
      EXPECT_GE(response.emitted_at_audio_s(), response.syllable().end_s());
    }
    accents += response.has_accent();
    if (response.has_summary()) {
      summary = true;
      EXPECT_EQ(response.summary().chunks(), seq);
      EXPECT_EQ(response.summary().syllables(), static_cast<uint64_t>(syllables));
    }
  }
  const grpc::Status status = stream->Finish();
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_TRUE(info_first);
  EXPECT_TRUE(summary);
  EXPECT_GT(syllables, 15);
  EXPECT_GT(accents, 3);
}

TEST_F(ProsodyServiceTest, StreamRejectsChunksOutOfSequence) {
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  auto stream = stub_->StreamAnalyze(&ctx);
  v1::StreamAnalyzeRequest config;
  config.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
  config.mutable_config()->mutable_format()->set_sample_rate_hz(48000);
  config.mutable_config()->mutable_format()->set_channels(2);
  stream->Write(config);
  v1::StreamAnalyzeRequest chunk;
  chunk.mutable_chunk()->set_sequence_number(0);
  chunk.mutable_chunk()->set_data(std::string(4 * 480, '\0'));
  stream->Write(chunk);
  chunk.mutable_chunk()->set_sequence_number(5);
  stream->Write(chunk);
  stream->WritesDone();
  v1::StreamAnalyzeResponse response;
  while (stream->Read(&response)) {
  }
  const grpc::Status status = stream->Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(status.error_message(), "chunk.sequence_number"))
      << status.error_message();
}

// AnalyzeChunked: the recording as chunks (a minute of real speech: the
// LibriVox clips one after the other, 16 kHz mono F32LE in 1 s chunks, as
// `kinemo animate` sends it) gives the track Analyze gives for the same
// samples, frames included (sent apart, in batches).
std::vector<float> LibriVoxMinute() {
  std::vector<float> out;
  while (out.size() < 60 * 16000) {
    for (const char* id : {"0870", "0880", "0890", "0920", "0930"}) {
      auto a = audio::DecodeAudioFile(std::string(KINEMO_TEST_DATA_DIR) +
                                      "/speech/sense_and_sensibility_01_austen_64kb-" + id + ".wav");
      EXPECT_TRUE(a.ok() && a->sample_rate_hz == 16000);
      if (!a.ok()) return out;
      out.insert(out.end(), a->samples.begin(), a->samples.end());
      out.resize(out.size() + 8000, 0.0f);  // half a second of pause
    }
  }
  out.resize(60 * 16000);
  return out;
}

std::string F32(const float* samples, size_t n) {
  return std::string(reinterpret_cast<const char*>(samples), n * sizeof(float));
}

// Sends `samples` through AnalyzeChunked in chunks of `chunk` samples: the
// result and the frames gathered into one response.
grpc::Status AnalyzeInChunks(v1::ProsodyService::Stub* stub, const std::vector<float>& samples, size_t chunk,
                             v1::AnalyzeResponse* out, int* frame_batches, const v1::FaceParams* face = nullptr,
                             int* face_batches = nullptr) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  auto stream = stub->AnalyzeChunked(&ctx);
  v1::AnalyzeChunkedRequest config;
  auto* c = config.mutable_config();
  c->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  c->mutable_format()->set_sample_rate_hz(16000);
  c->mutable_format()->set_channels(1);
  c->set_expected_duration_s(static_cast<double>(samples.size()) / 16000);
  if (face != nullptr) *c->mutable_face() = *face;
  bool open = stream->Write(config);
  uint64_t seq = 0;
  for (size_t i = 0; open && i < samples.size(); i += chunk) {
    v1::AnalyzeChunkedRequest q;
    q.mutable_chunk()->set_sequence_number(seq++);
    q.mutable_chunk()->set_data(F32(samples.data() + i, std::min(chunk, samples.size() - i)));
    open = stream->Write(q);
  }
  if (open) stream->WritesDone();
  v1::AnalyzeChunkedResponse r;
  *frame_batches = 0;
  bool first = true;
  while (stream->Read(&r)) {
    if (first) {
      EXPECT_TRUE(r.has_result()) << "the result comes first";
      first = false;
    }
    if (r.has_result()) {
      EXPECT_EQ(r.result().track().frames_size(), 0) << "frames come apart";
      EXPECT_EQ(r.result().track().face_size(), 0) << "the face comes apart";
      *out = r.result();
    } else if (r.has_face()) {
      EXPECT_LE(r.face().frames_size(), 5000);
      EXPECT_LT(r.ByteSizeLong(), 1u << 19);
      if (face_batches != nullptr) ++*face_batches;
      for (const auto& f : r.face().frames()) *out->mutable_track()->add_face() = f;
    } else {
      EXPECT_EQ(out->track().face_size(), 0) << "the face comes after the frames";
      ++*frame_batches;
      EXPECT_LE(r.frames().frames_size(), 10000);
      for (const auto& f : r.frames().frames()) *out->mutable_track()->add_frames() = f;
    }
  }
  return stream->Finish();
}

TEST_F(ProsodyServiceTest, AnalyzeChunkedGivesAnalyzesTrackForTheSameSamples) {
  const std::vector<float> samples = LibriVoxMinute();
  ASSERT_EQ(samples.size(), 60u * 16000);
  v1::AnalyzeRequest whole;
  whole.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  whole.mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
  whole.mutable_audio()->set_data(F32(samples.data(), samples.size()));
  v1::AnalyzeResponse expected;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  ASSERT_TRUE(stub_->Analyze(&ctx, whole, &expected).ok());
  ASSERT_GT(expected.track().syllables_size(), 100);
  v1::AnalyzeResponse got;
  int batches = 0;
  const grpc::Status s = AnalyzeInChunks(stub_.get(), samples, 16000, &got, &batches);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(batches, 1);  // 6000 frames
  v1::ProsodyTrack a = expected.track(), b = got.track();
  EXPECT_EQ(a.SerializeAsString(), b.SerializeAsString())
      << "syllables " << a.syllables_size() << " vs " << b.syllables_size() << ", frames " << a.frames_size()
      << " vs " << b.frames_size();
  // Chunks of any size (a prime number of samples) give the same.
  v1::AnalyzeResponse odd;
  ASSERT_TRUE(AnalyzeInChunks(stub_.get(), samples, 15013, &odd, &batches).ok());
  EXPECT_EQ(odd.track().SerializeAsString(), a.SerializeAsString());
}

// Longer than Analyze takes (this server's max_audio_s is 60 s): Analyze
// says where longer recordings go, AnalyzeChunked takes it.
TEST_F(ProsodyServiceTest, LongerThanAnalyzeTakesGoesThroughAnalyzeChunked) {
  std::vector<float> samples = LibriVoxMinute();
  const std::vector<float> minute = samples;
  samples.insert(samples.end(), minute.begin(), minute.begin() + 10 * 16000);  // 70 s
  v1::AnalyzeRequest whole;
  whole.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  whole.mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
  whole.mutable_audio()->set_data(F32(samples.data(), samples.size()));
  v1::AnalyzeResponse response;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  const grpc::Status s = stub_->Analyze(&ctx, whole, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "audio.data: the recording is longer than max_audio_s (60 s)"))
      << s.error_message();
  EXPECT_TRUE(absl::StrContains(s.error_message(), "AnalyzeChunked")) << s.error_message();
  int batches = 0;
  const grpc::Status chunked = AnalyzeInChunks(stub_.get(), samples, 16000, &response, &batches);
  ASSERT_TRUE(chunked.ok()) << chunked.error_message();
  EXPECT_NEAR(response.track().duration_s(), 70, 0.01);
  EXPECT_EQ(response.track().frames_size(), 7000);
}

TEST_F(ProsodyServiceTest, AnalyzeChunkedRefusesBadMessagesNamingTheField) {
  struct Case {
    std::string name;
    std::function<void(v1::AnalyzeChunkedRequest*)> config;  // null: no config sent
    std::vector<std::pair<uint64_t, size_t>> chunks;        // (sequence number, bytes)
    std::string prefix;
  };
  auto f32 = [](v1::AnalyzeChunkedRequest* r) {
    r->mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
    r->mutable_config()->mutable_format()->set_sample_rate_hz(16000);
  };
  const std::vector<Case> cases = {
      {"no config", nullptr, {{0, 64000}}, "config: must be the first message"},
      {"a file", [](v1::AnalyzeChunkedRequest* r) {
         r->mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
       }, {}, "config.format.encoding"},
      {"bad params", [&](v1::AnalyzeChunkedRequest* r) {
         f32(r);
         r->mutable_config()->mutable_params()->set_pitch_floor_hz(-1);
       }, {}, "config.params.pitch_floor_hz"},
      {"out of sequence", f32, {{0, 64000}, {2, 64000}}, "chunk.sequence_number: 2 out of sequence"},
      {"over a second", f32, {{0, 4 * 16001}}, "chunk.data"},
      {"partial frame", f32, {{0, 6}}, "chunk.data"},
      {"nothing sent", f32, {}, "chunk: no audio was sent"},
  };
  for (const Case& c : cases) {
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    auto stream = stub_->AnalyzeChunked(&ctx);
    if (c.config) {
      v1::AnalyzeChunkedRequest config;
      c.config(&config);
      stream->Write(config);
    }
    for (const auto& [seq, bytes] : c.chunks) {
      v1::AnalyzeChunkedRequest q;
      q.mutable_chunk()->set_sequence_number(seq);
      q.mutable_chunk()->set_data(std::string(bytes, '\0'));
      if (!stream->Write(q)) break;
    }
    stream->WritesDone();
    v1::AnalyzeChunkedResponse r;
    while (stream->Read(&r)) {
    }
    const grpc::Status s = stream->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.name << ": " << s.error_message();
    EXPECT_TRUE(absl::StartsWith(s.error_message(), c.prefix)) << c.name << ": " << s.error_message();
  }
}

// The speech face (docs/face.md) of a service whose store holds a face model
// trained on a real BEAT2 take: Analyze returns a frame every 10 ms over the
// recording, StreamAnalyze one batch per chunk up to the audio received; an
// unknown model is refused naming the request's field.
TEST(ProsodyServiceFace, AnalyzeAndStreamGiveTheSpeechFace) {
  kinemo::testing::TempDir dir;
  ASSERT_EQ(coordinator::MakeFaceStore(dir.File("store")), "");
  v1::ProsodyOptions options;
  options.set_store_dir(dir.File("store"));
  options.mutable_recognizer()->set_disabled(true);
  auto service = std::make_shared<ProsodyServiceImpl>(options);
  common::v1::ServerOptions server;
  server.set_host("127.0.0.1");
  server.set_port(0);
  auto host = server::ServiceHost::Start(server, "prosody", {{service, v1::ProsodyService::service_full_name()}});
  ASSERT_TRUE(host.ok()) << host.status();
  auto stub = v1::ProsodyService::NewStub((*host)->InProcessChannel());
  const std::string wav = ReadFile(std::string(KINEMO_TEST_DATA_DIR) + "/" + kClip);
  {
    v1::AnalyzeRequest request;
    request.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
    request.mutable_audio()->set_data(wav);
    request.mutable_face()->set_enabled(true);
    v1::AnalyzeResponse response;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    ASSERT_TRUE(stub->Analyze(&ctx, request, &response).ok());
    const auto& t = response.track();
    ASSERT_NEAR(t.face_size(), t.duration_s() / 0.01, 2);
    for (int k = 0; k < t.face_size(); ++k) {
      EXPECT_NEAR(t.face(k).time_s(), k * 0.01, 1e-9);
      ASSERT_EQ(t.face(k).classes_size(), 18);
    }
    request.mutable_face()->set_model_id("nobody");
    grpc::ClientContext ctx2;
    ctx2.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    const grpc::Status s = stub->Analyze(&ctx2, request, &response);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "face.model_id: no face model 'nobody'")) << s.error_message();
  }
  // AnalyzeChunked (config.face): a minute of speech in 1 s chunks gives
  // Analyze's speech face of the same samples, in batches after the frames.
  {
    const std::vector<float> samples = LibriVoxMinute();
    v1::AnalyzeRequest whole;
    whole.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
    whole.mutable_audio()->mutable_format()->set_sample_rate_hz(16000);
    whole.mutable_audio()->set_data(F32(samples.data(), samples.size()));
    whole.mutable_face()->set_enabled(true);
    v1::AnalyzeResponse expected;
    grpc::ClientContext c1;
    c1.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    ASSERT_TRUE(stub->Analyze(&c1, whole, &expected).ok());
    ASSERT_NEAR(expected.track().face_size(), 6000, 2);
    v1::FaceParams face;
    face.set_enabled(true);
    v1::AnalyzeResponse got;
    int frame_batches = 0, face_batches = 0;
    const grpc::Status s = AnalyzeInChunks(stub.get(), samples, 16000, &got, &frame_batches, &face, &face_batches);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(face_batches, 2);  // 6001 frames, at most 5000 a batch
    EXPECT_EQ(got.track().face_size(), expected.track().face_size());
    EXPECT_TRUE(got.track().SerializeAsString() == expected.track().SerializeAsString())
        << "AnalyzeChunked's track and face differ from Analyze's";
    // Without config.face: no face.
    v1::AnalyzeResponse plain;
    ASSERT_TRUE(AnalyzeInChunks(stub.get(), samples, 16000, &plain, &frame_batches).ok());
    EXPECT_EQ(plain.track().face_size(), 0);
    // Bad model ids are refused with the config, naming the field.
    const std::vector<float> second(samples.begin(), samples.begin() + 16000);
    struct Case {
      const char* id;
      grpc::StatusCode code;
      const char* message;
    };
    for (const Case& c : {Case{"Not an id!", grpc::StatusCode::INVALID_ARGUMENT,
                               "config.face.model_id: 'Not an id!' must be 1..64 characters of [a-z0-9_-]"},
                          Case{"nobody", grpc::StatusCode::NOT_FOUND,
                               "config.face.model_id: no face model 'nobody' in the store"}}) {
      face.set_model_id(c.id);
      v1::AnalyzeResponse bad;
      const grpc::Status e = AnalyzeInChunks(stub.get(), second, 16000, &bad, &frame_batches, &face);
      EXPECT_EQ(e.error_code(), c.code) << e.error_message();
      EXPECT_EQ(e.error_message(), c.message);
    }
  }
  // Live: 16 kHz PCM in 20 ms chunks; each chunk's batch reaches its end.
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto stream = stub->StreamAnalyze(&ctx);
  v1::StreamAnalyzeRequest config;
  config.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
  config.mutable_config()->mutable_format()->set_sample_rate_hz(16000);
  config.mutable_config()->mutable_format()->set_channels(1);
  config.mutable_config()->mutable_face()->set_enabled(true);
  ASSERT_TRUE(stream->Write(config));
  v1::StreamAnalyzeResponse r;
  ASSERT_TRUE(stream->Read(&r));
  ASSERT_TRUE(r.has_info());
  EXPECT_TRUE(r.info().face_running());
  for (uint64_t seq = 0; seq < 10; ++seq) {
    v1::StreamAnalyzeRequest chunk;
    chunk.mutable_chunk()->set_sequence_number(seq);
    chunk.mutable_chunk()->set_data(wav.substr(44 + seq * 640, 640));  // 320 samples of the clip's PCM
    ASSERT_TRUE(stream->Write(chunk));
    do {
      ASSERT_TRUE(stream->Read(&r));
    } while (!r.has_face());
    EXPECT_NEAR(r.face().frames(r.face().frames_size() - 1).time_s(), (seq + 1) * 0.02, 1e-9);
  }
  stream->WritesDone();
  while (stream->Read(&r)) {
  }
  EXPECT_TRUE(stream->Finish().ok());
  (*host)->Shutdown();
}

#ifdef KINEMO_WITH_SPHINX
// A server with the recognizer (skipped where the Sphinx models are missing).
class ProsodyServiceRecognizer : public ::testing::Test {
 protected:
  void SetUp() override {
    common::v1::ServerOptions server;
    server.set_host("127.0.0.1");
    server.set_port(0);
    service_ = std::make_shared<ProsodyServiceImpl>(v1::ProsodyOptions());
    if (service_->recognizer() == nullptr) GTEST_SKIP() << "CMU Sphinx models are not installed";
    auto host = server::ServiceHost::Start(server, "prosody", {{service_, v1::ProsodyService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = *std::move(host);
    stub_ = v1::ProsodyService::NewStub(host_->InProcessChannel());
  }
  void TearDown() override {
    if (host_) host_->Shutdown();
  }

  // Streams the 16 kHz clip in 100 ms chunks with `recognizer`; returns every
  // response and the call's status.
  grpc::Status StreamClip(const v1::RecognizerParams& recognizer, std::vector<v1::StreamAnalyzeResponse>* out) {
    const std::string pcm = ReadFile(std::string(KINEMO_TEST_DATA_DIR) + "/" + kClip).substr(44);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    auto stream = stub_->StreamAnalyze(&ctx);
    v1::StreamAnalyzeRequest config;
    config.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
    config.mutable_config()->mutable_format()->set_sample_rate_hz(16000);
    *config.mutable_config()->mutable_recognizer() = recognizer;
    stream->Write(config);
    const std::size_t chunk_bytes = 3200;  // 100 ms
    uint64_t seq = 0;
    for (std::size_t i = 0; i < pcm.size(); i += chunk_bytes) {
      v1::StreamAnalyzeRequest r;
      r.mutable_chunk()->set_sequence_number(seq++);
      r.mutable_chunk()->set_data(pcm.substr(i, std::min(chunk_bytes, pcm.size() - i)));
      if (!stream->Write(r)) break;
    }
    stream->WritesDone();
    v1::StreamAnalyzeResponse response;
    while (stream->Read(&response)) out->push_back(response);
    return stream->Finish();
  }

  std::shared_ptr<ProsodyServiceImpl> service_;
  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::ProsodyService::Stub> stub_;
};

// Live keyword spotting over gRPC: "consider" (2.9-3.4 s) is spotted while
// the stream runs, long before the end of the 7.1 s clip.
TEST_F(ProsodyServiceRecognizer, StreamSpotsKeywordsLive) {
  v1::RecognizerParams keywords;
  keywords.add_keywords("consider");
  std::vector<v1::StreamAnalyzeResponse> responses;
  const grpc::Status status = StreamClip(keywords, &responses);
  ASSERT_TRUE(status.ok()) << status.error_message();
  bool running = false;
  int consider = 0, phones = 0;
  uint64_t summary_words = 0;
  for (const auto& response : responses) {
    if (response.has_info()) running = response.info().recognizer_running();
    if (response.has_word()) {
      EXPECT_TRUE(response.word().keyword());
      if (response.word().word() == "consider" && response.word().start_s() > 2.7 && response.word().end_s() < 3.6) {
        ++consider;
        // Spotted live: within a second of the word's end, not at the end of the stream.
        EXPECT_LT(response.emitted_at_audio_s() - response.word().end_s(), 1.0);
      }
    }
    phones += response.has_phone();
    if (response.has_summary()) summary_words = response.summary().words();
  }
  EXPECT_TRUE(running);
  EXPECT_EQ(consider, 1);
  EXPECT_GE(summary_words, 1u);
  EXPECT_EQ(phones, 0);  // phones only with recognizer.enabled

  // Unknown words are refused naming the field.
  v1::RecognizerParams unknown;
  unknown.add_keywords("qzxv");
  responses.clear();
  const grpc::Status refused = StreamClip(unknown, &responses);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(refused.error_message(), "config.recognizer.keywords[0]")) << refused.error_message();
}

// Live timed phones (recognizer.enabled): phone events while the audio
// flows, within the phone stream's latency of their end (plus a chunk),
// tiling the clip; keywords at the same time.
TEST_F(ProsodyServiceRecognizer, StreamSendsPhonesLive) {
  v1::RecognizerParams both;
  both.set_enabled(true);
  both.add_keywords("power");
  std::vector<v1::StreamAnalyzeResponse> responses;
  const grpc::Status status = StreamClip(both, &responses);
  ASSERT_TRUE(status.ok()) << status.error_message();
  bool running = false;
  int power = 0, late = 0;
  std::vector<common::v1::Phone> phones;
  double audio_s = 0;
  for (const auto& response : responses) {
    if (response.has_info()) running = response.info().recognizer_running();
    if (response.has_word() && response.word().word() == "power") ++power;
    if (response.has_phone()) {
      phones.push_back(response.phone());
      // 0.39 s: PhoneStream::latency_s() for the server's 0.3 s lag.
      late += response.emitted_at_audio_s() - response.phone().end_s() > 0.39 + 0.1 + 0.011;
    }
    if (response.has_summary()) audio_s = response.summary().duration_s();
  }
  EXPECT_TRUE(running);
  EXPECT_EQ(power, 1);
  ASSERT_GT(phones.size(), 40u);
  EXPECT_LE(late, 3) << "of " << phones.size() << " phones came after the stream ended";
  EXPECT_NEAR(phones.front().start_s(), 0.0, 0.011);
  EXPECT_NEAR(phones.back().end_s(), audio_s, 0.05);
  for (std::size_t i = 1; i < phones.size(); ++i) {
    EXPECT_NEAR(phones[i].start_s(), phones[i - 1].end_s(), 0.011) << "phone " << i;
    EXPECT_LT(phones[i].start_s(), phones[i].end_s()) << "phone " << i;
  }
}
#endif

}  // namespace
}  // namespace kinemo::prosody
