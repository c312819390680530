// Decoding to mono float: encoded files/bytes (libsndfile) and headerless PCM.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/audio/audio.h"
#include "common/status/status.h"

namespace kinemo::audio {

// ---------------------------------------------------------------------------
// Encoded input (WAV, FLAC, OGG, ...), read through libsndfile.
// ---------------------------------------------------------------------------

// Decodes an encoded file held in memory (e.g. the bytes of a gRPC request).
// Errors: INVALID_ARGUMENT for anything wrong with the input or over a limit.
StatusOr<DecodedAudio> DecodeAudio(std::span<const std::uint8_t> bytes,
                                   const DecodeOptions& options = {});
StatusOr<DecodedAudio> DecodeAudio(std::string_view bytes,
                                   const DecodeOptions& options = {});

// Reads `path` (size checked against limits.max_bytes before reading) and
// decodes it as DecodeAudio does. Messages start with the path.
// Errors: NOT_FOUND if the file does not exist; otherwise as DecodeAudio.
StatusOr<DecodedAudio> DecodeAudioFile(const std::string& path,
                                       const DecodeOptions& options = {});

// Containers and sample formats this libsndfile build can read, as
// "flac: FLAC (Free Lossless Audio Codec)" lines (for --help and logs).
std::vector<std::string> SupportedFormats();

// ---------------------------------------------------------------------------
// Headerless PCM (gRPC chunks, .raw files).
// ---------------------------------------------------------------------------

enum class PcmEncoding {
  kS16Le,  // "s16le": signed 16-bit little-endian
  kS24Le,  // "s24le": signed 24-bit little-endian, packed in 3 bytes
  kS32Le,  // "s32le": signed 32-bit little-endian
  kF32Le,  // "f32le": IEEE float 32-bit little-endian
  kF64Le,  // "f64le": IEEE float 64-bit little-endian
  kU8,     // "u8":    unsigned 8-bit, 128 = silence
};

// "s16le" → kS16Le, ... Error names the accepted encodings.
StatusOr<PcmEncoding> ParsePcmEncoding(std::string_view name);
std::string_view PcmEncodingName(PcmEncoding encoding);
int BytesPerSample(PcmEncoding encoding);

struct RawPcmFormat {
  PcmEncoding encoding = PcmEncoding::kS16Le;
  int sample_rate_hz = 16000;
  int channels = 1;
};

// Converts whole frames of headerless PCM to mono float and appends them to
// `out` (no allocation when `out` has the capacity: fit for live chunks).
// A partial trailing frame is an INVALID_ARGUMENT error naming the byte
// count; nothing is appended on error. `non_finite_count`, if given, is
// increased by the samples zeroed under NonFinitePolicy::kZero.
Status AppendPcmAsMono(std::span<const std::uint8_t> bytes,
                       PcmEncoding encoding, int channels,
                       NonFinitePolicy non_finite, std::vector<float>& out,
                       int64_t* non_finite_count = nullptr);

// Decodes a whole headerless PCM buffer, with the same limits and result as
// DecodeAudio (format "raw", subtype the encoding name).
StatusOr<DecodedAudio> DecodeRawPcm(std::span<const std::uint8_t> bytes,
                                    const RawPcmFormat& format,
                                    const DecodeOptions& options = {});
StatusOr<DecodedAudio> DecodeRawPcm(std::string_view bytes,
                                    const RawPcmFormat& format,
                                    const DecodeOptions& options = {});
StatusOr<DecodedAudio> DecodeRawPcmFile(const std::string& path,
                                        const RawPcmFormat& format,
                                        const DecodeOptions& options = {});

// Reads a whole file, refusing files larger than `max_bytes` before reading.
StatusOr<std::vector<std::uint8_t>> ReadFileBytes(const std::string& path,
                                                  std::size_t max_bytes);

}  // namespace kinemo::audio
