// Prosody benchmarks: offline analysis speed (x real time on one core) on
// real speech, live analysis speed, and the live latency of syllable events
// (audio time from a syllable's end trough to its event) at 10 ms chunks.
// Reads ../shared/data/speech when present (the 69 s ZEGGS monologue and the
// LibriVox clips), else tests/data/speech, and says which.
//
// Side by side with Praat: bench/prosody_vs_praat.sh.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "services/prosody/core/analyzer.h"
#include "services/prosody/core/streaming.h"

namespace {

struct Corpus {
  std::vector<std::vector<float>> clips;  // 16 kHz mono
  double seconds = 0;
  std::string source;
};

const Corpus& LoadCorpus() {
  static const Corpus corpus = [] {
    Corpus c;
    std::vector<std::string> files;
    const std::string shared = std::string(KINEMO_SHARED_DATA_DIR) + "/speech";
    const std::string local = std::string(KINEMO_TEST_DATA_DIR) + "/speech";
    const std::string dir = std::filesystem::exists(shared) ? shared : local;
    c.source = dir;
    for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
      if (e.path().extension() == ".wav") files.push_back(e.path().string());
    }
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      auto a = kinemo::audio::DecodeAudioFile(f);
      if (!a.ok()) continue;
      auto r = kinemo::audio::ToAnalysisRate(*std::move(a), 16000);
      if (!r.ok()) continue;
      c.seconds += r->duration_s;
      c.clips.push_back(std::move(r->samples));
    }
    std::fprintf(stderr, "prosody bench corpus: %zu files, %.1f s from %s\n", c.clips.size(),
                 c.seconds, dir.c_str());
    return c;
  }();
  return corpus;
}

void BM_ProsodyOffline(benchmark::State& state) {
  const Corpus& c = LoadCorpus();
  for (auto _ : state) {
    for (const auto& clip : c.clips) {
      auto r = kinemo::prosody::AnalyzeSamples(clip, 16000, {});
      benchmark::DoNotOptimize(r);
    }
  }
  state.counters["x_real_time"] = benchmark::Counter(
      c.seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ProsodyOffline)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

void BM_ProsodyLive(benchmark::State& state) {
  const Corpus& c = LoadCorpus();
  const std::size_t chunk = static_cast<std::size_t>(state.range(0));
  std::vector<double> latencies;
  for (auto _ : state) {
    latencies.clear();
    for (const auto& clip : c.clips) {
      auto a = kinemo::prosody::StreamingAnalyzer::Create(16000, {}, false);
      std::vector<kinemo::prosody::StreamEvent> events;
      for (std::size_t i = 0; i < clip.size(); i += chunk) {
        events.clear();
        (void)(*a)->Push(std::span(clip).subspan(i, std::min(chunk, clip.size() - i)), &events);
        for (const auto& e : events) {
          if (e.kind == kinemo::prosody::StreamEvent::Kind::kSyllable) {
            latencies.push_back(e.emitted_at_s - e.syllable.end_s);
          }
        }
      }
      events.clear();
      (*a)->Finish(&events);
    }
  }
  state.counters["x_real_time"] = benchmark::Counter(
      c.seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  if (!latencies.empty()) {
    std::sort(latencies.begin(), latencies.end());
    state.counters["syllable_latency_p50_ms"] = 1000 * latencies[latencies.size() / 2];
    state.counters["syllable_latency_p99_ms"] =
        1000 * latencies[std::min(latencies.size() - 1, latencies.size() * 99 / 100)];
    state.counters["syllables"] = static_cast<double>(latencies.size());
  }
}
BENCHMARK(BM_ProsodyLive)->Arg(160)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

}  // namespace
