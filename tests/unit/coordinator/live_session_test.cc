// The live session's pacing of the planner (core/live_session.h): the audio
// clock reaches the planner only when a chunk completes a frame, and every
// frame the planner's emit rule makes from every chunk's advance is still
// made, on real speech cut in the 20 ms chunks live clients send.
#include "services/coordinator/core/live_session.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/audio/decode.h"

namespace kinemo::coordinator {
namespace {

namespace pl = ::kinemo::planner::v1;

struct Recorder : LiveOutput {
  void ToProsody(prosody::v1::StreamAnalyzeRequest r) override { prosody.push_back(std::move(r)); }
  void ToInference(inference::v1::StreamInferRequest, bool) override {}
  void ToPlanner(pl::ControlRequest r, bool) override { planner.push_back(std::move(r)); }
  void ToClient(coordinator::v1::StreamAnimateResponse) override {}
  std::vector<prosody::v1::StreamAnalyzeRequest> prosody;
  std::vector<pl::ControlRequest> planner;
};

// Frames the planner emits up to `advance` (controller_rpcs.cc: times
// k·dt < advance − 0.001·dt, from 0).
std::int64_t FramesBefore(double advance, double dt) {
  std::int64_t n = 0;
  while (static_cast<double>(n) * dt < advance - 1e-3 * dt) ++n;
  return n;
}

TEST(LiveSession, AdvancesThePlannerOnlyWhenAChunkCompletesAFrame) {
  auto audio = audio::DecodeAudioFile(std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2/2_scott_0_2_2.wav");
  ASSERT_TRUE(audio.ok()) << audio.status();
  const int rate = audio->sample_rate_hz;
  v1::StreamAnimateConfig config;
  config.mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_S16LE);
  config.mutable_format()->set_sample_rate_hz(rate);
  config.mutable_format()->set_channels(1);
  config.mutable_models()->set_inference_model_id("crf");
  config.mutable_models()->set_controller_id("gc");
  Recorder out;
  auto session = LiveSession::Create(config, v1::CoordinatorOptions(), {true, true, true}, 64 << 20, &out);
  ASSERT_TRUE(session.ok()) << session.status();
  (*session)->Start();
  ASSERT_EQ(out.planner.size(), 1u);  // the config
  ASSERT_TRUE(out.planner[0].has_config());

  const double dt = 1.0 / 30;
  pl::ControlResponse header;
  header.mutable_header()->set_frame_time_s(dt);
  ASSERT_TRUE((*session)->OnPlanner(header).ok());

  // 3 s of the take in 20 ms chunks of 16-bit PCM.
  const int per_chunk = rate / 50;
  const int chunks = 150;
  ASSERT_GE(audio->samples.size(), static_cast<std::size_t>(per_chunk * chunks));
  std::vector<double> every_chunk_end;
  for (int c = 0; c < chunks; ++c) {
    std::string bytes(static_cast<std::size_t>(per_chunk) * 2, '\0');
    for (int i = 0; i < per_chunk; ++i) {
      const float x = audio->samples[static_cast<std::size_t>(c * per_chunk + i)];
      const auto v = static_cast<std::int16_t>(std::lround(std::clamp(x, -1.0f, 1.0f) * 32767.0f));
      bytes[2 * i] = static_cast<char>(v & 0xff);
      bytes[2 * i + 1] = static_cast<char>((v >> 8) & 0xff);
    }
    v1::StreamAnimateRequest r;
    r.mutable_chunk()->set_sequence_number(static_cast<std::uint64_t>(c));
    r.mutable_chunk()->set_data(bytes);
    ASSERT_TRUE((*session)->OnClientMessage(r).ok());
    every_chunk_end.push_back(static_cast<double>((c + 1) * per_chunk) / rate);
  }
  EXPECT_EQ(out.prosody.size(), 1u + chunks);  // the config, then every chunk

  std::vector<double> advances;
  for (const auto& q : out.planner)
    if (q.message_case() == pl::ControlRequest::kAdvanceToS) advances.push_back(q.advance_to_s());
  // 3 s at 30 fps: 90 frames, one advance for each chunk that completes one
  // (150 chunks sent), each making at least one new frame.
  ASSERT_FALSE(advances.empty());
  EXPECT_EQ(advances.size(), static_cast<std::size_t>(FramesBefore(every_chunk_end.back(), dt)));
  std::int64_t made = 0;
  for (double a : advances) {
    const std::int64_t n = FramesBefore(a, dt);
    EXPECT_GT(n, made) << "an advance to " << a << " s makes no frame";
    made = n;
  }
  // The same frames as an advance for every chunk: up to the audio received
  // (the last chunk, ending at 3.0 s, completes none: frame 89 is at 2.967 s).
  EXPECT_EQ(made, FramesBefore(every_chunk_end.back(), dt));
  EXPECT_LT(advances.back(), every_chunk_end.back());
  for (double t : every_chunk_end) {
    // After each chunk the planner had been told of every frame it completed.
    std::int64_t told = 0;
    for (double a : advances)
      if (a <= t + 1e-12) told = FramesBefore(a, dt);
    EXPECT_EQ(told, FramesBefore(t, dt)) << "after the chunk ending at " << t << " s";
  }
}

}  // namespace
}  // namespace kinemo::coordinator
