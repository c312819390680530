// The face's per-stream cost live (docs/face.md): the prosody service's
// speech face (MFCC + the live head + the HMM filter) per second of audio in
// 20 ms chunks, against the live prosody analysis it runs beside
// (BM_ProsodyLive... in prosody_bench.cc); the coordinator's composition of
// one face frame (30 per second of a stream). The model is trained on one
// BEAT2 take (tests/data/paired/beat2), the audio is the other take.
#include <benchmark/benchmark.h>

#include <memory>

#include "common/face/face_compose.h"
#include "services/prosody/core/face_corpus.h"
#include "services/prosody/core/face_model.h"

namespace {

struct FaceBenchData {
  std::shared_ptr<const kinemo::prosody::FaceModel> model;
  std::vector<float> audio;  // 16 kHz
};

const FaceBenchData& Data() {
  static const FaceBenchData d = [] {
    FaceBenchData out;
    const std::string dir = std::string(KINEMO_TEST_DATA_DIR) + "/paired/beat2";
    auto train = kinemo::prosody::ReadFaceTake(dir, "2_scott_0_1_1");
    auto test = kinemo::prosody::ReadFaceTake(dir, "2_scott_0_2_2");
    if (!train.ok() || !test.ok()) return out;
    auto m = kinemo::prosody::TrainFaceModel(std::span(&*train, 1), {});
    if (!m.ok()) return out;
    out.model = std::make_shared<const kinemo::prosody::FaceModel>(*std::move(m));
    out.audio = std::move(test->samples);
    return out;
  }();
  return d;
}

// One stream's live speech face over 10 s of real speech, 20 ms chunks;
// items = seconds of audio (so items/s = real-time factor on one core).
void BM_FaceStreamLive(benchmark::State& state) {
  const FaceBenchData& d = Data();
  if (!d.model) {
    state.SkipWithError("no BEAT2 take");
    return;
  }
  const std::size_t n = std::min<std::size_t>(d.audio.size(), 160000), chunk = 320;
  std::vector<kinemo::face::SpeechFaceFrame> out;
  out.reserve(1100);
  for (auto _ : state) {
    kinemo::prosody::FaceStream s(d.model);
    out.clear();
    for (std::size_t i = 0; i + chunk <= n; i += chunk) s.Push(std::span<const float>(d.audio).subspan(i, chunk), &out);
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(n / 16000));
}
BENCHMARK(BM_FaceStreamLive)->Unit(benchmark::kMillisecond);

// The coordinator's face frame: composing one frame from the speech face.
void BM_FaceCompose(benchmark::State& state) {
  const FaceBenchData& d = Data();
  if (!d.model) {
    state.SkipWithError("no BEAT2 take");
    return;
  }
  const auto speech = kinemo::prosody::AnalyzeFace(std::span<const float>(d.audio).first(160000), *d.model);
  int64_t frames = 0;
  for (auto _ : state) {
    kinemo::face::FaceComposer c;
    for (const auto& s : speech) c.AddSpeech(s);
    for (double t = 0; t < 9.9; t += 1.0 / 30) {
      benchmark::DoNotOptimize(c.Compose(t));
      ++frames;
    }
  }
  state.SetItemsProcessed(frames);
}
BENCHMARK(BM_FaceCompose)->Unit(benchmark::kMillisecond);

}  // namespace
