// kinemo_audio: decode audio (any container libsndfile reads, or headerless
// PCM) to mono float, resample it to an analysis rate, and write WAV.
//
// One path for files and for gRPC bytes: everything is decoded from an
// in-memory buffer through libsndfile's virtual I/O. Limits are checked
// before any heavy work (size first, then the header's rate, channels and
// duration), and every error is a kinemo::Status whose message starts with
// the field or the thing that is wrong, e.g.
//   "audio.sample_rate_hz: 4000 is below the minimum 8000 (limits.min_sample_rate_hz)"
//   "wav: truncated data chunk: header declares 882000 bytes, only 1000 present"
//
// Choices (documented here, tested in tests/unit/audio):
//   * Channels are mixed to mono by averaging.
//   * Integer PCM is scaled to [-1, 1): s16 / 32768, s24 / 2^23, s32 / 2^31,
//     u8 (x - 128) / 128 — the same scaling libsndfile uses, for files and raw.
//   * Float files keep their values (samples beyond ±1 are not clipped).
//   * NaN or Inf samples are rejected by default (NonFinitePolicy::kReject);
//     kZero replaces them with 0 and counts them in DecodedAudio.
//   * A WAV whose data chunk declares more bytes than the buffer holds is an
//     error by default (libsndfile would silently read what is there); set
//     DecodeOptions::allow_truncated to accept the frames that are present.
//     A declared size of 0 or 0xFFFFFFFF (streamed WAV of unknown length) is
//     accepted as "until the end of the buffer".
//   * Zero frames is an error by default (nothing to analyse).
//   * Only the containers in DecodeOptions::accepted_formats are opened
//     (default: wav, wavex, rf64, w64, aiff, flac, ogg (Vorbis/Opus), mpeg
//     (MP3)); libsndfile's exotic readers are refused for untrusted bytes.
//     Debian 12's libsndfile 1.2.0 reads all of these; WAV (u8/16/24/32-bit
//     PCM, float, double, WAVEX), AIFF, FLAC, OGG/Vorbis, OGG/Opus and MP3
//     are tested. MP3 frame counts come from the decoder (not checked for
//     truncation).
//   * The RIFF size field is not checked (libsndfile ignores it too); only
//     the data chunk is. Other header damage is reported with libsndfile's
//     message ("audio: cannot decode N bytes starting with 'RIFF': ...").
//
// Thread safety: all functions may run concurrently on different inputs.
// (libsndfile's message for a failed open comes from a process-wide slot, so
// two concurrent failures may swap their texts; codes are unaffected.)
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "common/status/status.h"

namespace kinemo::audio {

// Limits on what is accepted. Checked before the samples are decoded.
struct AudioLimits {
  double max_duration_s = 3600.0;          // longest input accepted
  int min_sample_rate_hz = 8000;           // lowest rate accepted
  int max_sample_rate_hz = 192000;         // highest rate accepted
  int max_channels = 8;                    // most channels accepted
  std::size_t max_bytes = 512u << 20;      // largest encoded input (512 MiB)
};

// Checks the limits themselves (e.g. min > max). Field names start with
// "limits.".
Status ValidateLimits(const AudioLimits& limits);

// Checks a stream's rate, channel count and duration against `limits`.
// `frames` < 0 means "unknown" (not checked). Field names start with "audio.".
Status CheckAgainstLimits(int sample_rate_hz, int channels, int64_t frames,
                          const AudioLimits& limits);

enum class NonFinitePolicy {
  kReject,  // a NaN/Inf sample is an INVALID_ARGUMENT error naming its index
  kZero,    // replaced by 0 and counted in DecodedAudio::non_finite_samples
};

struct DecodeOptions {
  AudioLimits limits;
  NonFinitePolicy non_finite = NonFinitePolicy::kReject;
  // Accept a WAV whose data chunk is shorter than its header declares.
  bool allow_truncated = false;
  // Accept input with zero frames (returns an empty DecodedAudio).
  bool allow_empty = false;
  // Short container names (see DecodedAudio::format) that may be opened.
  std::vector<std::string> accepted_formats = {"wav",  "wavex", "rf64", "w64",
                                               "aiff", "flac",  "ogg",  "mpeg"};
};

// Decoded audio, mixed to mono.
struct DecodedAudio {
  std::vector<float> samples;  // mono, nominally in [-1, 1]
  int sample_rate_hz = 0;
  int channels = 0;            // channels in the source, before mixing
  std::string format;          // short container name: "wav", "flac", "raw", ...
  std::string subtype;         // short sample format: "pcm_16", "float", "vorbis", ...
  std::string format_description;   // libsndfile's name, e.g. "WAV (Microsoft)"
  std::string subtype_description;  // e.g. "Signed 16 bit PCM"
  double duration_s = 0.0;     // samples.size() / sample_rate_hz
  // Statistics over every sample of every source channel (before mixing).
  float peak = 0.0f;           // max |x|
  double rms = 0.0;            // sqrt(mean(x^2))
  int64_t non_finite_samples = 0;  // replaced by 0 (NonFinitePolicy::kZero)

  int64_t frames() const { return static_cast<int64_t>(samples.size()); }
};

// Linear amplitude → dBFS (20·log10). 0 gives -infinity.
inline double ToDbfs(double linear) {
  if (linear <= 0.0) return -std::numeric_limits<double>::infinity();
  return 20.0 * std::log10(linear);
}

}  // namespace kinemo::audio
