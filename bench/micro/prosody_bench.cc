// Prosody benchmarks: offline analysis speed (x real time on one core) on
// real speech; one long recording (the corpus end to end up to 9.2 minutes,
// the ZEGGS x 8) on 1 and 2 threads (wall clock: all threads work on
// one file); live analysis speed, and the live latency of syllable events
// (audio time from a syllable's end trough to its event) at 10 ms chunks;
// timed phones (the recognizer: before, the phone loop; now, the words found
// and aligned; the phone grammar of live streams), CPU seconds per second of
// audio on one core.
// Reads ../shared/data/speech when present (the 69 s ZEGGS monologue and the
// LibriVox clips), else tests/data/speech, and says which.
//
// Side by side with Praat: bench/tools/prosody_vs_praat.sh. Phone quality against
// a forced alignment of the transcript: bench/tools/phone_eval.cc.
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
#ifdef KINEMO_WITH_SPHINX
#include "services/prosody/core/recognizer.h"
#endif

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
  kinemo::prosody::AnalysisOptions options;
  options.threads = 1;
  for (auto _ : state) {
    for (const auto& clip : c.clips) {
      auto r = kinemo::prosody::AnalyzeSamples(clip, 16000, options);
      benchmark::DoNotOptimize(r);
    }
  }
  state.counters["x_real_time"] = benchmark::Counter(
      c.seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ProsodyOffline)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

// One 9.2-minute recording on state.range(0) threads; x_real_time by the
// wall clock (the time is real time: all threads work on the one file).
void BM_ProsodyLongFile(benchmark::State& state) {
  const Corpus& c = LoadCorpus();
  static const std::vector<float> long_file = [&c] {
    std::vector<float> out;
    const std::size_t target = static_cast<std::size_t>(9.2 * 60 * 16000);
    while (out.size() < target) {
      for (const auto& clip : c.clips) out.insert(out.end(), clip.begin(), clip.end());
    }
    out.resize(target);
    return out;
  }();
  kinemo::prosody::AnalysisOptions options;
  options.threads = static_cast<int>(state.range(0));
  for (auto _ : state) {
    auto r = kinemo::prosody::AnalyzeSamples(long_file, 16000, options);
    benchmark::DoNotOptimize(r);
  }
  state.counters["x_real_time"] = benchmark::Counter(
      static_cast<double>(long_file.size()) / 16000 * static_cast<double>(state.iterations()),
      benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ProsodyLongFile)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()
    ->MeasureProcessCPUTime();

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

#ifdef KINEMO_WITH_SPHINX
// Timed phones of the corpus on one core (models loaded beforehand):
// 0 = the phone loop used before (with Sphinx's default word search, as
// `--recognize` ran both), 1 = words and phones now (the words found,
// aligned), 2 = the phone grammar alone (live streams). rtf = CPU seconds
// per second of audio.
void BM_TimedPhones(benchmark::State& state) {
  const Corpus& c = LoadCorpus();
  kinemo::prosody::RecognizerConfig config;
  if (state.range(0) == 0) {
    config.phone_search = kinemo::prosody::LegacyPhoneSearch();
    config.word_search = kinemo::prosody::LegacyWordSearch();
  } else if (state.range(0) == 2) {
    config.phone_search.method = kinemo::prosody::PhoneMethod::kPhoneGrammar;
  }
  auto recognizer = kinemo::prosody::SphinxRecognizer::Create(config);
  if (!recognizer.ok() || !(*recognizer)->LoadModels().ok()) {
    state.SkipWithError("the Sphinx models are not installed");
    return;
  }
  (void)(*recognizer)->Phones(c.clips.front());  // a phone decoder too
  for (auto _ : state) {
    for (const auto& clip : c.clips) {
      auto r = state.range(0) == 2 ? (*recognizer)->Phones(clip).status() : (*recognizer)->Recognize(clip).status();
      benchmark::DoNotOptimize(r);
    }
  }
  state.counters["rtf"] = benchmark::Counter(
      c.seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["x_real_time"] = benchmark::Counter(
      c.seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_TimedPhones)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

// Live phones: the corpus in 20 ms chunks through a PhoneStream.
void BM_PhoneStream(benchmark::State& state) {
  const Corpus& c = LoadCorpus();
  auto recognizer = kinemo::prosody::SphinxRecognizer::Create({});
  if (!recognizer.ok()) {
    state.SkipWithError("the Sphinx models are not installed");
    return;
  }
  std::vector<kinemo::prosody::RecognizedPhone> phones;
  for (auto _ : state) {
    for (const auto& clip : c.clips) {
      auto stream = (*recognizer)->OpenPhoneStream(0.3);
      if (!stream.ok()) {
        state.SkipWithError("no phone stream");
        return;
      }
      for (std::size_t i = 0; i < clip.size(); i += 320) {
        phones.clear();
        (void)(*stream)->Process(std::span(clip).subspan(i, std::min<std::size_t>(320, clip.size() - i)), &phones);
      }
      (void)(*stream)->Finish(&phones);
    }
  }
  state.counters["rtf"] = benchmark::Counter(
      c.seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_PhoneStream)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();
#endif

}  // namespace
