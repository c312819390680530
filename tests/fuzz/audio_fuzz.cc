// Fuzzes the audio decoder (common/audio): encoded bytes through libsndfile
// (WAV, FLAC, OGG, MP3, ... as DecodeAudio accepts them from a gRPC request),
// the same bytes as headerless PCM in a format taken from the input's last
// byte (raw files and live chunks), and the resampling to the analysis rate
// that prosody applies to whatever decoded.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "common/audio/decode.h"
#include "common/audio/resample.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

using kinemo::audio::DecodedAudio;

void CheckDecoded(const DecodedAudio& audio) {
  KINEMO_FUZZ_CHECK(audio.sample_rate_hz >= 8000 && audio.sample_rate_hz <= 192000,
                    "rate outside the limits");
  KINEMO_FUZZ_CHECK(audio.channels >= 1 && audio.channels <= 8, "channels outside the limits");
  for (float x : audio.samples) KINEMO_FUZZ_CHECK(std::isfinite(x), "non-finite sample accepted");
  // Prosody analyses at 16 kHz; keep the work per input small.
  if (audio.samples.size() <= 200000) {
    auto at16k = kinemo::audio::ToAnalysisRate(audio, 16000);
    KINEMO_FUZZ_CHECK(at16k.ok(), at16k.status().ToString());
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::span<const uint8_t> bytes(data, size);
  auto decoded = kinemo::audio::DecodeAudio(bytes);
  if (decoded.ok()) {
    CheckDecoded(*decoded);
  } else {
    KINEMO_FUZZ_CHECK_REFUSED(decoded.status(), absl::StatusCode::kInvalidArgument);
  }

  // Headerless PCM: encoding, channels and rate from the last byte.
  if (size == 0) return 0;
  const uint8_t selector = data[size - 1];
  kinemo::audio::RawPcmFormat format;
  format.encoding = static_cast<kinemo::audio::PcmEncoding>(selector % 6);
  format.channels = 1 + (selector / 6) % 9;  // 9 channels: over the limit
  format.sample_rate_hz = (selector & 0x80) ? 48000 : 16000;
  const std::span<const uint8_t> pcm = bytes.first(size - 1);
  auto raw = kinemo::audio::DecodeRawPcm(pcm, format);
  if (raw.ok()) {
    CheckDecoded(*raw);
  } else {
    KINEMO_FUZZ_CHECK_REFUSED(raw.status(), absl::StatusCode::kInvalidArgument);
  }
  // Live chunks: appended with NaN/Inf replaced by zeros, never rejected.
  std::vector<float> out;
  int64_t zeroed = 0;
  const auto s = kinemo::audio::AppendPcmAsMono(
      pcm, format.encoding, format.channels, kinemo::audio::NonFinitePolicy::kZero, out, &zeroed);
  if (s.ok()) {
    for (float x : out) KINEMO_FUZZ_CHECK(std::isfinite(x), "non-finite sample after kZero");
  }
  return 0;
}
