// kinemo_audio benchmarks: WAV decode throughput and decode + resample to the
// 16 kHz analysis rate, as MB/s of encoded input and × real time (seconds of
// audio per second of wall time, one thread).
//
// Speech: KINEMO_SHARED_DATA_DIR/speech (../shared/data) when present — the
// five LibriVox clips joined (24.7 s) and the 69 s ZEGGS monologue — else the
// LibriVox copies in tests/data/speech (no ZEGGS), and it says so. Variants
// (48 kHz stereo, 44.1 kHz mono, 48 kHz float) are made from that speech in
// memory before timing.
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "common/audio/wav_writer.h"

namespace kinemo::audio {
namespace {

namespace fs = std::filesystem;

struct BenchInput {
  std::vector<std::uint8_t> bytes;  // an encoded WAV file image
  double duration_s = 0.0;
  int sample_rate_hz = 0;
  int channels = 0;
};

// Source speech by name ("librivox", "zeggs"): 16 kHz mono samples.
std::vector<float> LoadSpeech(const std::string& name) {
  const fs::path shared = fs::path(KINEMO_SHARED_DATA_DIR) / "speech";
  std::vector<fs::path> paths;
  if (name == "zeggs") {
    paths = {shared / "zeggs" / "067_Speech_2_x_1_0.wav"};
  } else {
    fs::path dir = shared / "librivox";
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) {
      std::fprintf(stderr, "audio_bench: %s not found; using tests/data/speech copies\n",
                   dir.string().c_str());
      dir = fs::path(KINEMO_TEST_DATA_DIR) / "speech";
    }
    for (const char* id : {"0870", "0880", "0890", "0920", "0930"}) {
      paths.push_back(dir / (std::string("sense_and_sensibility_01_austen_64kb-") + id + ".wav"));
    }
  }
  std::vector<float> speech;
  for (const fs::path& p : paths) {
    auto audio = DecodeAudioFile(p.string());
    if (!audio.ok()) {
      std::fprintf(stderr, "audio_bench: %s\n", std::string(audio.status().message()).c_str());
      continue;
    }
    speech.insert(speech.end(), audio->samples.begin(), audio->samples.end());
  }
  return speech;
}

// "<speech>/<variant>": the speech encoded as a WAV of that shape.
const BenchInput& Input(const std::string& speech_name, const std::string& variant) {
  static std::map<std::string, BenchInput> cache;
  const std::string key = speech_name + "/" + variant;
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  const std::vector<float> speech = LoadSpeech(speech_name);
  BenchInput input;
  std::vector<float> samples = speech;
  WavSampleFormat format = WavSampleFormat::kPcm16;
  input.sample_rate_hz = 16000;
  input.channels = 1;
  if (variant == "44k1_mono_pcm16") {
    samples = *Resample(speech, 16000, 44100);
    input.sample_rate_hz = 44100;
  } else if (variant == "48k_stereo_pcm16") {
    const auto up = *Resample(speech, 16000, 48000);
    samples.clear();
    for (float x : up) {
      samples.push_back(x);
      samples.push_back(0.8f * x);
    }
    input.sample_rate_hz = 48000;
    input.channels = 2;
  } else if (variant == "48k_mono_float") {
    samples = *Resample(speech, 16000, 48000);
    input.sample_rate_hz = 48000;
    format = WavSampleFormat::kFloat32;
  }
  input.bytes = *EncodeWav(samples, input.sample_rate_hz, input.channels, format);
  input.duration_s = static_cast<double>(samples.size() / input.channels) / input.sample_rate_hz;
  return cache.emplace(key, std::move(input)).first->second;
}

void SetCounters(benchmark::State& state, const BenchInput& input) {
  const auto iterations = static_cast<double>(state.iterations());
  state.SetBytesProcessed(static_cast<int64_t>(input.bytes.size()) * state.iterations());
  state.counters["MB_per_s"] =
      benchmark::Counter(static_cast<double>(input.bytes.size()) * iterations / 1e6,
                         benchmark::Counter::kIsRate);
  state.counters["x_realtime"] =
      benchmark::Counter(input.duration_s * iterations, benchmark::Counter::kIsRate);
  state.counters["audio_s"] = input.duration_s;
}

void BM_DecodeWav(benchmark::State& state, std::string speech, std::string variant) {
  const BenchInput& input = Input(speech, variant);
  for (auto _ : state) {
    auto audio = DecodeAudio(std::span<const std::uint8_t>(input.bytes));
    if (!audio.ok()) {
      state.SkipWithError(std::string(audio.status().message()).c_str());
      break;
    }
    benchmark::DoNotOptimize(audio->samples.data());
  }
  SetCounters(state, input);
}

void BM_DecodeResample16k(benchmark::State& state, std::string speech, std::string variant) {
  const BenchInput& input = Input(speech, variant);
  for (auto _ : state) {
    auto audio = DecodeAudio(std::span<const std::uint8_t>(input.bytes));
    if (!audio.ok()) {
      state.SkipWithError(std::string(audio.status().message()).c_str());
      break;
    }
    auto analysis = ToAnalysisRate(*std::move(audio), 16000);
    if (!analysis.ok()) {
      state.SkipWithError(std::string(analysis.status().message()).c_str());
      break;
    }
    benchmark::DoNotOptimize(analysis->samples.data());
  }
  SetCounters(state, input);
}

// Live path: 10 ms chunks of 48 kHz mono through the streaming resampler.
void BM_StreamResample48kTo16k(benchmark::State& state, std::string speech) {
  const BenchInput& input = Input(speech, "48k_mono_float");
  const auto decoded = DecodeAudio(std::span<const std::uint8_t>(input.bytes));
  const std::vector<float>& samples = decoded->samples;
  std::vector<float> out;
  out.reserve(samples.size() / 3 + 8192);
  constexpr std::size_t kChunk = 480;
  for (auto _ : state) {
    auto resampler = StreamingResampler::Create(48000, 16000);
    out.clear();
    for (std::size_t pos = 0; pos < samples.size(); pos += kChunk) {
      const std::size_t n = std::min(kChunk, samples.size() - pos);
      (void)resampler->Process(std::span(samples).subspan(pos, n), out);
    }
    (void)resampler->Flush(out);
    benchmark::DoNotOptimize(out.data());
  }
  const auto iterations = static_cast<double>(state.iterations());
  state.counters["x_realtime"] =
      benchmark::Counter(input.duration_s * iterations, benchmark::Counter::kIsRate);
  state.counters["audio_s"] = input.duration_s;
}

// Headerless s16le (gRPC chunks) → mono float.
void BM_RawPcmS16(benchmark::State& state, std::string speech) {
  const BenchInput& input = Input(speech, "16k_mono_pcm16");
  const std::span<const std::uint8_t> pcm = std::span(input.bytes).subspan(44);
  std::vector<float> out;
  out.reserve(pcm.size() / 2);
  for (auto _ : state) {
    out.clear();
    (void)AppendPcmAsMono(pcm, PcmEncoding::kS16Le, 1, NonFinitePolicy::kReject, out);
    benchmark::DoNotOptimize(out.data());
  }
  const auto iterations = static_cast<double>(state.iterations());
  state.SetBytesProcessed(static_cast<int64_t>(pcm.size()) * state.iterations());
  state.counters["MB_per_s"] = benchmark::Counter(static_cast<double>(pcm.size()) * iterations / 1e6,
                                                  benchmark::Counter::kIsRate);
  state.counters["x_realtime"] =
      benchmark::Counter(input.duration_s * iterations, benchmark::Counter::kIsRate);
}

const bool kRegistered = [] {
  std::vector<std::string> speeches = {"librivox"};
  std::error_code ec;
  if (fs::exists(fs::path(KINEMO_SHARED_DATA_DIR) / "speech" / "zeggs" / "067_Speech_2_x_1_0.wav",
                 ec)) {
    speeches.push_back("zeggs");
    benchmark::AddCustomContext("audio_bench.speech", "shared/data/speech: librivox + zeggs");
  } else {
    benchmark::AddCustomContext("audio_bench.speech",
                                "tests/data/speech (librivox only; shared/data absent)");
  }
  for (const std::string& s : speeches) {
    for (const char* v : {"16k_mono_pcm16", "44k1_mono_pcm16", "48k_stereo_pcm16", "48k_mono_float"}) {
      benchmark::RegisterBenchmark(("BM_AudioDecodeWav/" + s + "_" + v).c_str(), BM_DecodeWav, s,
                                   std::string(v))
          ->Unit(benchmark::kMillisecond);
    }
    for (const char* v : {"44k1_mono_pcm16", "48k_stereo_pcm16"}) {
      benchmark::RegisterBenchmark(("BM_AudioDecodeResample16k/" + s + "_" + v).c_str(),
                                   BM_DecodeResample16k, s, std::string(v))
          ->Unit(benchmark::kMillisecond);
    }
    benchmark::RegisterBenchmark(("BM_AudioStreamResample48kTo16k_10ms/" + s).c_str(),
                                 BM_StreamResample48kTo16k, s)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("BM_AudioRawPcmS16/" + s).c_str(), BM_RawPcmS16, s)
        ->Unit(benchmark::kMillisecond);
  }
  return true;
}();

}  // namespace
}  // namespace kinemo::audio
