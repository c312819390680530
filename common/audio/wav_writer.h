// Writing WAV (libsndfile), to memory or to a file.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::audio {

enum class WavSampleFormat {
  kPcmU8,    // 8-bit unsigned PCM
  kPcm16,    // 16-bit signed PCM
  kPcm24,    // 24-bit signed PCM
  kPcm32,    // 32-bit signed PCM
  kFloat32,  // IEEE float 32
  kFloat64,  // IEEE float 64
};

std::string_view WavSampleFormatName(WavSampleFormat format);

// Encodes interleaved samples (frames × channels) as a WAV file image.
// Integer formats clip to [-1, 1]; NaN/Inf samples are an error naming the
// index. More than 2 channels or > 32-bit formats are written as WAVEX
// (WAVE_FORMAT_EXTENSIBLE) by libsndfile's rules.
StatusOr<std::vector<std::uint8_t>> EncodeWav(std::span<const float> interleaved,
                                              int sample_rate_hz, int channels,
                                              WavSampleFormat format);

// EncodeWav, then writes the bytes to `path` (replaced if present).
Status WriteWavFile(const std::string& path, std::span<const float> interleaved,
                    int sample_rate_hz, int channels, WavSampleFormat format);

}  // namespace kinemo::audio
