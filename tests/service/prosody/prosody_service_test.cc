// The prosody gRPC service in process (ServiceHost + InProcessChannel) on
// real LibriVox speech from tests/data/speech.
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/match.h"
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
