// GMG / BodySpeech benchmarks: graph build over the gesture phrases of the
// Bandai-Namco gesture clips (target: ≥ 261 phrases in ≤ 1 s) and synthesis
// speed (target: ≥ 1000x real time, i.e. a minute of speech in ≤ 60 ms,
// prosody excluded) on the pitch accents of the 69 s ZEGGS monologue.
// Reads ../shared/data when present, else tests/data, and says which.
// Counters: phrases, speech_s, x_real_time.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "common/audio/decode.h"
#include "services/planner/gesture/graph.h"
#include "services/planner/gesture/phrases.h"
#include "services/planner/gesture/synthesis.h"
#include "services/planner/library/library.h"
#include "services/prosody/core/pipeline.h"

namespace {

namespace gs = kinemo::planner::gesture;

struct Setup {
  std::shared_ptr<const kinemo::planner::Library> library;
  gs::PhraseSet phrases;
  std::shared_ptr<const gs::GestureGraph> graph;
  std::vector<gs::AccentInput> accents;
  double speech_s = 0;
};

const Setup& GetSetup() {
  static const Setup s = [] {
    Setup s;
    namespace fs = std::filesystem;
    const std::string shared_motion = std::string(KINEMO_SHARED_DATA_DIR) + "/motion/bandai-dataset-1";
    kinemo::planner::LibrarySources src;
    if (fs::exists(shared_motion)) {
      const std::vector<std::string> gestures = {"bow", "bye", "byebye", "guide", "respond", "call"};
      for (const auto& e : fs::directory_iterator(shared_motion)) {
        auto name = kinemo::planner::ParseBandaiName(e.path().stem().string());
        if (e.path().extension() != ".bvh" || !name) continue;
        if (std::find(gestures.begin(), gestures.end(), name->content) != gestures.end()) {
          src.paths.push_back(e.path().string());
        }
      }
      std::sort(src.paths.begin(), src.paths.end());
    } else {
      src.paths = {std::string(KINEMO_TEST_DATA_DIR) + "/planner_gesture"};
    }
    auto lib = kinemo::planner::LoadLibrary("bench", src);
    if (!lib.ok()) {
      std::fprintf(stderr, "gesture bench: %s\n", std::string(lib.status().message()).c_str());
      std::abort();
    }
    s.library = *std::move(lib);
    s.phrases = *gs::ExtractPhrases(*s.library);
    s.graph = *gs::GestureGraph::Build(s.library, s.phrases, {});
    const std::string zeggs = std::string(KINEMO_SHARED_DATA_DIR) + "/speech/zeggs/067_Speech_2_x_1_0.wav";
    const std::string speech = fs::exists(zeggs) ? zeggs
                                                 : std::string(KINEMO_TEST_DATA_DIR) +
                                                       "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";
    auto audio = kinemo::audio::DecodeAudioFile(speech);
    auto r = kinemo::prosody::RunPipeline(audio->samples, audio->sample_rate_hz, {}, nullptr);
    s.speech_s = r->prosody.duration_s;
    for (const auto& a : r->prosody.accents) s.accents.push_back({a.time_s, a.strength, a.psi});
    std::fprintf(stderr, "gesture bench: %zu clips, %zu phrases (%s); %zu accents in %.1f s of speech (%s)\n",
                 s.library->clips.size(), s.phrases.phrases.size(), src.paths.front().c_str(), s.accents.size(),
                 s.speech_s, speech.c_str());
    return s;
  }();
  return s;
}

void BM_GmgBuild(benchmark::State& state) {
  const Setup& s = GetSetup();
  for (auto _ : state) {
    auto g = gs::GestureGraph::Build(s.library, s.phrases, {});
    benchmark::DoNotOptimize(g);
  }
  state.counters["phrases"] = static_cast<double>(s.phrases.phrases.size());
}
BENCHMARK(BM_GmgBuild)->Unit(benchmark::kMillisecond);

void BM_GmgSweep8(benchmark::State& state) {
  const Setup& s = GetSetup();
  for (auto _ : state) {
    auto rows = gs::GestureGraph::Sweep(*s.library, s.phrases, {0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0}, {});
    benchmark::DoNotOptimize(rows);
  }
}
BENCHMARK(BM_GmgSweep8)->Unit(benchmark::kMillisecond);

void BM_Synthesize(benchmark::State& state) {
  const Setup& s = GetSetup();
  const auto alg = state.range(0) == 0 ? gs::Algorithm::kGmg : gs::Algorithm::kBodySpeech;
  gs::SynthesisParams p;
  p.duration_s = s.speech_s;
  for (auto _ : state) {
    auto r = gs::Synthesize(*s.graph, s.accents, alg, p);
    benchmark::DoNotOptimize(r);
  }
  state.counters["speech_s"] = s.speech_s;
  state.counters["x_real_time"] = benchmark::Counter(s.speech_s * static_cast<double>(state.iterations()),
                                                     benchmark::Counter::kIsRate);
  state.SetLabel(alg == gs::Algorithm::kGmg ? "GMG" : "BodySpeech");
}
BENCHMARK(BM_Synthesize)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace
