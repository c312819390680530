#include "common/audio/wav_writer.h"

#include <sndfile.h>

#include <cmath>
#include <fstream>

#include "absl/strings/str_cat.h"
#include "common/audio/sndfile_memory.h"

namespace kinemo::audio {

std::string_view WavSampleFormatName(WavSampleFormat format) {
  switch (format) {
    case WavSampleFormat::kPcmU8: return "pcm_u8";
    case WavSampleFormat::kPcm16: return "pcm_16";
    case WavSampleFormat::kPcm24: return "pcm_24";
    case WavSampleFormat::kPcm32: return "pcm_32";
    case WavSampleFormat::kFloat32: return "float";
    case WavSampleFormat::kFloat64: return "double";
  }
  return "?";
}

StatusOr<std::vector<std::uint8_t>> EncodeWav(std::span<const float> interleaved,
                                              int sample_rate_hz, int channels,
                                              WavSampleFormat format) {
  if (sample_rate_hz <= 0) {
    return InvalidField("wav.sample_rate_hz", sample_rate_hz, " is not a valid rate (must be > 0)");
  }
  if (channels < 1 || channels > 1024) {
    return InvalidField("wav.channels", channels, " is not a valid channel count (1..1024)");
  }
  if (interleaved.size() % static_cast<std::size_t>(channels) != 0) {
    return InvalidField("wav.samples", interleaved.size(), " samples is not a multiple of ",
                        channels, " channels");
  }
  for (std::size_t i = 0; i < interleaved.size(); ++i) {
    if (!std::isfinite(interleaved[i])) {
      return InvalidField(kinemo::StrCat("wav.samples[", i, "]"), "NaN/Inf cannot be written");
    }
  }
  int subtype = SF_FORMAT_PCM_16;
  switch (format) {
    case WavSampleFormat::kPcmU8: subtype = SF_FORMAT_PCM_U8; break;
    case WavSampleFormat::kPcm16: subtype = SF_FORMAT_PCM_16; break;
    case WavSampleFormat::kPcm24: subtype = SF_FORMAT_PCM_24; break;
    case WavSampleFormat::kPcm32: subtype = SF_FORMAT_PCM_32; break;
    case WavSampleFormat::kFloat32: subtype = SF_FORMAT_FLOAT; break;
    case WavSampleFormat::kFloat64: subtype = SF_FORMAT_DOUBLE; break;
  }
  SF_INFO info{};
  info.samplerate = sample_rate_hz;
  info.channels = channels;
  info.format = (channels > 2 ? SF_FORMAT_WAVEX : SF_FORMAT_WAV) | subtype;
  if (sf_format_check(&info) == 0) {
    return InvalidField("wav.format", "libsndfile cannot write ", WavSampleFormatName(format),
                        " with ", channels, " channels");
  }
  std::vector<std::uint8_t> bytes;
  internal::MemoryWriter writer{&bytes, 0};
  {
    internal::SndfilePtr file(sf_open_virtual(internal::WriterIo(), SFM_WRITE, &info, &writer));
    if (file == nullptr) {
      return absl::InternalError(kinemo::StrCat("wav: cannot open writer: ", sf_strerror(nullptr)));
    }
    sf_command(file.get(), SFC_SET_CLIPPING, nullptr, SF_TRUE);
    const auto frames = static_cast<sf_count_t>(interleaved.size() / channels);
    if (frames > 0 && sf_writef_float(file.get(), interleaved.data(), frames) != frames) {
      return absl::InternalError(kinemo::StrCat("wav: write failed: ", sf_strerror(file.get())));
    }
  }  // sf_close writes the final header sizes
  return bytes;
}

Status WriteWavFile(const std::string& path, std::span<const float> interleaved,
                    int sample_rate_hz, int channels, WavSampleFormat format) {
  auto bytes = EncodeWav(interleaved, sample_rate_hz, channels, format);
  if (!bytes.ok()) return Annotate(bytes.status(), path);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return absl::PermissionDeniedError(kinemo::StrCat(path, ": cannot open for writing"));
  out.write(reinterpret_cast<const char*>(bytes->data()),
            static_cast<std::streamsize>(bytes->size()));
  out.close();
  if (!out) return absl::DataLossError(kinemo::StrCat(path, ": write failed"));
  return absl::OkStatus();
}

}  // namespace kinemo::audio
