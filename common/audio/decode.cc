#include "common/audio/decode.h"

#include <sndfile.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "common/audio/sndfile_memory.h"

namespace kinemo::audio {
namespace {

using internal::MemoryReader;
using internal::SndfilePtr;

constexpr sf_count_t kBlockFrames = 4096;

// Running statistics over every source sample (all channels).
struct Stats {
  float peak = 0.0f;
  double sum_squares = 0.0;
  int64_t count = 0;
};

void FinishStats(const Stats& stats, DecodedAudio& audio) {
  audio.peak = stats.peak;
  audio.rms = stats.count > 0 ? std::sqrt(stats.sum_squares / static_cast<double>(stats.count))
                              : 0.0;
}

Status NonFiniteError(int64_t sample_index, int channels, int sample_rate_hz, float value) {
  const int64_t frame = sample_index / std::max(channels, 1);
  return InvalidField(
      kinemo::StrCat("audio.samples[", sample_index, "]"),
      absl::StrFormat("%s at frame %d (channel %d, t=%.4f s) is not a valid sample; "
                      "use NonFinitePolicy::kZero to replace such samples by 0",
                      std::isnan(value) ? "NaN" : "Inf", frame,
                      sample_index % std::max(channels, 1),
                      sample_rate_hz > 0 ? static_cast<double>(frame) / sample_rate_hz : 0.0));
}

// Mixes `frames` interleaved frames into `mono`, updating statistics and
// handling non-finite samples. `first_sample` is the index of in[0] in the
// whole stream (for error messages).
Status MixToMono(float* in, int64_t frames, int channels, int sample_rate_hz,
                 NonFinitePolicy policy, int64_t first_sample, float* mono, Stats& stats,
                 int64_t& non_finite) {
  const int64_t n = frames * channels;
  float peak = stats.peak;
  double sum_squares = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    float x = in[i];
    if (!std::isfinite(x)) [[unlikely]] {
      if (policy == NonFinitePolicy::kReject) {
        return NonFiniteError(first_sample + i, channels, sample_rate_hz, x);
      }
      ++non_finite;
      x = 0.0f;
      in[i] = 0.0f;
    }
    peak = std::max(peak, std::fabs(x));
    sum_squares += static_cast<double>(x) * x;
  }
  stats.peak = peak;
  stats.sum_squares += sum_squares;
  stats.count += n;
  // Channels are summed in double: the sum of finite floats near the float
  // limit overflows a float, their mean never does.
  if (channels == 1) {
    if (mono != in) std::memcpy(mono, in, static_cast<std::size_t>(frames) * sizeof(float));
  } else if (channels == 2) {
    for (int64_t f = 0; f < frames; ++f) {
      mono[f] = static_cast<float>(0.5 * (static_cast<double>(in[2 * f]) + in[2 * f + 1]));
    }
  } else {
    for (int64_t f = 0; f < frames; ++f) {
      const float* frame = in + f * channels;
      double sum = 0.0;
      for (int c = 0; c < channels; ++c) sum += frame[c];
      mono[f] = static_cast<float>(sum / channels);
    }
  }
  return absl::OkStatus();
}

std::string Magic(std::span<const std::uint8_t> bytes) {
  std::string magic;
  for (std::size_t i = 0; i < std::min<std::size_t>(bytes.size(), 4); ++i) {
    const unsigned char c = bytes[i];
    if (std::isprint(c)) {
      magic += static_cast<char>(c);
    } else {
      magic += absl::StrFormat("\\x%02x", c);
    }
  }
  return magic;
}

uint32_t Le32(const std::uint8_t* p) {
  return static_cast<uint32_t>(p[0]) | (static_cast<uint32_t>(p[1]) << 8) |
         (static_cast<uint32_t>(p[2]) << 16) | (static_cast<uint32_t>(p[3]) << 24);
}

// libsndfile reads what is present when a WAV data chunk is shorter than its
// header says, with no error; this compares the data chunk's declared size
// with the bytes actually present.
Status CheckRiffDataChunk(std::span<const std::uint8_t> bytes, bool allow_truncated) {
  if (allow_truncated) return absl::OkStatus();
  const auto damage =
      internal::FindRiffDamage(bytes.size(), [&](std::uint64_t pos, std::uint8_t* out, std::size_t n) {
        if (pos + n > bytes.size()) return false;
        std::memcpy(out, bytes.data() + pos, n);
        return true;
      });
  if (!damage) return absl::OkStatus();
  if (damage->truncated_data) {
    return InvalidField("wav", kinemo::StrCat("truncated data chunk: header declares ", damage->declared,
                                              " bytes at offset ", damage->offset, ", only ", damage->available,
                                              " present (", damage->declared - damage->available,
                                              " missing); set DecodeOptions::allow_truncated to read what is there"));
  }
  return InvalidField("wav", kinemo::StrCat("truncated chunk header at offset ", damage->offset, " (",
                                            damage->available, " of 8 bytes) before any data chunk"));
}

// ---------------------------------------------------------------------------
// Headerless PCM conversion.
// ---------------------------------------------------------------------------

template <PcmEncoding E>
inline float ReadPcm(const std::uint8_t* p) {
  if constexpr (E == PcmEncoding::kS16Le) {
    const auto v = static_cast<int16_t>(static_cast<uint16_t>(p[0] | (p[1] << 8)));
    return static_cast<float>(v) * (1.0f / 32768.0f);
  } else if constexpr (E == PcmEncoding::kS24Le) {
    const uint32_t u = static_cast<uint32_t>(p[0]) << 8 | static_cast<uint32_t>(p[1]) << 16 |
                       static_cast<uint32_t>(p[2]) << 24;
    return static_cast<float>(static_cast<int32_t>(u) >> 8) * (1.0f / 8388608.0f);
  } else if constexpr (E == PcmEncoding::kS32Le) {
    return static_cast<float>(static_cast<double>(static_cast<int32_t>(Le32(p))) *
                              (1.0 / 2147483648.0));
  } else if constexpr (E == PcmEncoding::kF32Le) {
    return std::bit_cast<float>(Le32(p));
  } else if constexpr (E == PcmEncoding::kF64Le) {
    const uint64_t u = static_cast<uint64_t>(Le32(p)) | (static_cast<uint64_t>(Le32(p + 4)) << 32);
    const double v = std::bit_cast<double>(u);
    // Beyond the float range is not a sample: ±Inf, handled as non-finite.
    if (std::fabs(v) > std::numeric_limits<float>::max()) {
      return v > 0 ? std::numeric_limits<float>::infinity()
                   : -std::numeric_limits<float>::infinity();
    }
    return static_cast<float>(v);
  } else {
    return (static_cast<float>(p[0]) - 128.0f) * (1.0f / 128.0f);
  }
}

template <PcmEncoding E>
Status ConvertPcm(const std::uint8_t* bytes, int64_t frames, int channels,
                  NonFinitePolicy policy, int sample_rate_hz, float* mono, Stats* stats,
                  int64_t& non_finite) {
  constexpr int kBytes = E == PcmEncoding::kS16Le   ? 2
                         : E == PcmEncoding::kS24Le ? 3
                         : E == PcmEncoding::kS32Le ? 4
                         : E == PcmEncoding::kF32Le ? 4
                         : E == PcmEncoding::kF64Le ? 8
                                                    : 1;
  constexpr bool kFloat = E == PcmEncoding::kF32Le || E == PcmEncoding::kF64Le;
  float peak = stats != nullptr ? stats->peak : 0.0f;
  double sum_squares = 0.0;
  const std::uint8_t* p = bytes;
  for (int64_t f = 0; f < frames; ++f) {
    double sum = 0.0;  // in double: a float sum of large samples overflows
    for (int c = 0; c < channels; ++c, p += kBytes) {
      float x = ReadPcm<E>(p);
      if constexpr (kFloat) {
        if (!std::isfinite(x)) [[unlikely]] {
          if (policy == NonFinitePolicy::kReject) {
            return NonFiniteError(f * channels + c, channels, sample_rate_hz, x);
          }
          ++non_finite;
          x = 0.0f;
        }
      }
      if (stats != nullptr) {
        peak = std::max(peak, std::fabs(x));
        sum_squares += static_cast<double>(x) * x;
      }
      sum += x;
    }
    mono[f] = static_cast<float>(channels == 1 ? sum : sum / channels);
  }
  if (stats != nullptr) {
    stats->peak = peak;
    stats->sum_squares += sum_squares;
    stats->count += frames * channels;
  }
  return absl::OkStatus();
}

Status AppendPcmImpl(std::span<const std::uint8_t> bytes, PcmEncoding encoding, int channels,
                     int sample_rate_hz, NonFinitePolicy policy, std::vector<float>& out,
                     int64_t* non_finite_count, Stats* stats) {
  if (channels < 1) {
    return InvalidField("raw.channels", channels, " is not a valid channel count (must be >= 1)");
  }
  const int bytes_per_sample = BytesPerSample(encoding);
  const std::size_t frame_bytes = static_cast<std::size_t>(bytes_per_sample) * channels;
  if (bytes.size() % frame_bytes != 0) {
    return InvalidField(
        "raw.bytes",
        kinemo::StrCat(bytes.size(), " bytes is not a whole number of ", frame_bytes, "-byte frames (",
                     PcmEncodingName(encoding), " x ", channels, " channel", channels == 1 ? "" : "s",
                     "): ", bytes.size() % frame_bytes, " trailing byte",
                     bytes.size() % frame_bytes == 1 ? "" : "s", " of a partial frame"));
  }
  const auto frames = static_cast<int64_t>(bytes.size() / frame_bytes);
  const std::size_t old_size = out.size();
  out.resize(old_size + static_cast<std::size_t>(frames));
  float* mono = out.data() + old_size;
  int64_t non_finite = 0;
  Status status;
  switch (encoding) {
    case PcmEncoding::kS16Le:
      status = ConvertPcm<PcmEncoding::kS16Le>(bytes.data(), frames, channels, policy,
                                               sample_rate_hz, mono, stats, non_finite);
      break;
    case PcmEncoding::kS24Le:
      status = ConvertPcm<PcmEncoding::kS24Le>(bytes.data(), frames, channels, policy,
                                               sample_rate_hz, mono, stats, non_finite);
      break;
    case PcmEncoding::kS32Le:
      status = ConvertPcm<PcmEncoding::kS32Le>(bytes.data(), frames, channels, policy,
                                               sample_rate_hz, mono, stats, non_finite);
      break;
    case PcmEncoding::kF32Le:
      status = ConvertPcm<PcmEncoding::kF32Le>(bytes.data(), frames, channels, policy,
                                               sample_rate_hz, mono, stats, non_finite);
      break;
    case PcmEncoding::kF64Le:
      status = ConvertPcm<PcmEncoding::kF64Le>(bytes.data(), frames, channels, policy,
                                               sample_rate_hz, mono, stats, non_finite);
      break;
    case PcmEncoding::kU8:
      status = ConvertPcm<PcmEncoding::kU8>(bytes.data(), frames, channels, policy,
                                            sample_rate_hz, mono, stats, non_finite);
      break;
  }
  if (!status.ok()) {
    out.resize(old_size);
    return status;
  }
  if (non_finite_count != nullptr) *non_finite_count += non_finite;
  return absl::OkStatus();
}

std::span<const std::uint8_t> AsBytes(std::string_view s) {
  return {reinterpret_cast<const std::uint8_t*>(s.data()), s.size()};
}

Status CheckSize(std::size_t size, const DecodeOptions& options) {
  if (size > options.limits.max_bytes) {
    return InvalidField("audio.bytes", size, " bytes exceed the limit of ", options.limits.max_bytes,
                        " bytes (limits.max_bytes)");
  }
  return absl::OkStatus();
}

}  // namespace

namespace internal {

std::optional<RiffDamage> FindRiffDamage(std::uint64_t size, const ReadAt& read) {
  std::uint8_t head[12];
  if (size < 12 || !read(0, head, 12)) return std::nullopt;
  if (std::memcmp(head, "RIFF", 4) != 0 || std::memcmp(head + 8, "WAVE", 4) != 0) return std::nullopt;
  uint64_t pos = 12;
  while (pos + 8 <= size) {
    std::uint8_t chunk[8];
    if (!read(pos, chunk, 8)) return std::nullopt;
    const uint32_t declared = Le32(chunk + 4);
    if (std::memcmp(chunk, "data", 4) == 0) {
      const uint64_t available = size - (pos + 8);
      // 0 and 0xFFFFFFFF mark a streamed WAV whose length was not known.
      if (declared != 0 && declared != 0xFFFFFFFFu && declared > available) {
        return RiffDamage{true, declared, pos + 8, available};
      }
      return std::nullopt;
    }
    pos += 8 + static_cast<uint64_t>(declared) + (declared & 1u);
  }
  // The input ends inside a chunk header, before any data chunk.
  if (pos < size) return RiffDamage{false, 8, pos, size - pos};
  return std::nullopt;  // no data chunk found: libsndfile reports it
}

}  // namespace internal

// ---------------------------------------------------------------------------
// Limits.
// ---------------------------------------------------------------------------

Status ValidateLimits(const AudioLimits& limits) {
  if (!(limits.max_duration_s > 0.0) || !std::isfinite(limits.max_duration_s)) {
    return InvalidField("limits.max_duration_s", "must be a finite number > 0, got ",
                        limits.max_duration_s);
  }
  if (limits.min_sample_rate_hz < 1) {
    return InvalidField("limits.min_sample_rate_hz", "must be >= 1, got ",
                        limits.min_sample_rate_hz);
  }
  if (limits.max_sample_rate_hz < limits.min_sample_rate_hz) {
    return InvalidField("limits.max_sample_rate_hz", limits.max_sample_rate_hz,
                        " is below limits.min_sample_rate_hz ", limits.min_sample_rate_hz);
  }
  if (limits.max_channels < 1) {
    return InvalidField("limits.max_channels", "must be >= 1, got ", limits.max_channels);
  }
  if (limits.max_bytes == 0) {
    return InvalidField("limits.max_bytes", "must be > 0");
  }
  return absl::OkStatus();
}

Status CheckAgainstLimits(int sample_rate_hz, int channels, int64_t frames,
                          const AudioLimits& limits) {
  if (sample_rate_hz <= 0) {
    return InvalidField("audio.sample_rate_hz", sample_rate_hz, " is not a valid rate (must be > 0)");
  }
  if (sample_rate_hz < limits.min_sample_rate_hz || sample_rate_hz > limits.max_sample_rate_hz) {
    return InvalidField("audio.sample_rate_hz", sample_rate_hz,
                        " is not a supported rate (", limits.min_sample_rate_hz, "..",
                        limits.max_sample_rate_hz,
                        " Hz; limits.min_sample_rate_hz/max_sample_rate_hz)");
  }
  if (channels < 1) {
    return InvalidField("audio.channels", channels, " is not a valid channel count (must be >= 1)");
  }
  if (channels > limits.max_channels) {
    return InvalidField("audio.channels", channels, " exceeds the limit of ", limits.max_channels,
                        " (limits.max_channels)");
  }
  if (frames >= 0) {
    const double duration_s = static_cast<double>(frames) / sample_rate_hz;
    if (duration_s > limits.max_duration_s) {
      return InvalidField("audio.duration_s",
                          absl::StrFormat("%.3f s (%d frames at %d Hz) exceeds the limit of %g s "
                                          "(limits.max_duration_s)",
                                          duration_s, frames, sample_rate_hz,
                                          limits.max_duration_s));
    }
  }
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------
// Encoded input.
// ---------------------------------------------------------------------------

StatusOr<DecodedAudio> DecodeAudio(std::span<const std::uint8_t> bytes,
                                   const DecodeOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateLimits(options.limits));
  if (bytes.empty()) return InvalidField("audio.bytes", "empty input (0 bytes)");
  KINEMO_RETURN_IF_ERROR(CheckSize(bytes.size(), options));
  KINEMO_RETURN_IF_ERROR(CheckRiffDataChunk(bytes, options.allow_truncated));

  MemoryReader reader{bytes.data(), static_cast<sf_count_t>(bytes.size()), 0};
  SF_INFO info{};
  SndfilePtr file(sf_open_virtual(internal::ReaderIo(), SFM_READ, &info, &reader));
  if (file == nullptr) {
    return InvalidField("audio",
                        kinemo::StrCat("cannot decode ", bytes.size(), " bytes starting with '",
                                     Magic(bytes), "': ", sf_strerror(nullptr)));
  }

  DecodedAudio audio;
  audio.format = internal::MajorFormatName(info.format);
  audio.subtype = internal::SubtypeName(info.format);
  audio.format_description = internal::MajorFormatDescription(info.format);
  audio.subtype_description = internal::SubtypeDescription(info.format);
  audio.sample_rate_hz = info.samplerate;
  audio.channels = info.channels;
  if (std::find(options.accepted_formats.begin(), options.accepted_formats.end(), audio.format) ==
      options.accepted_formats.end()) {
    return InvalidField("audio.format",
                        kinemo::StrCat("'", audio.format, "' (", audio.format_description,
                                     ") is not accepted (accepted: ",
                                     absl::StrJoin(options.accepted_formats, ", "),
                                     "; DecodeOptions::accepted_formats)"));
  }
  KINEMO_RETURN_IF_ERROR(
      CheckAgainstLimits(info.samplerate, info.channels, info.frames, options.limits));

  const bool frames_exact = (info.format & SF_FORMAT_TYPEMASK) != SF_FORMAT_MPEG;
  const int channels = info.channels;
  const auto max_frames =
      static_cast<int64_t>(std::floor(options.limits.max_duration_s * info.samplerate));
  // Reserve what the header declares, but never more than the bytes could
  // plausibly decode to (16 frames per byte is beyond any real codec's
  // ratio): a 45-byte FLAC header declaring an hour at 192 kHz must not
  // allocate 2.7 GB up front. The vector grows if the stream really is longer.
  if (info.frames > 0) {
    const auto plausible = static_cast<sf_count_t>(16 * bytes.size()) + kBlockFrames;
    audio.samples.reserve(static_cast<std::size_t>(std::min(info.frames, plausible)));
  }

  std::vector<float> block;
  if (channels > 1) block.resize(static_cast<std::size_t>(kBlockFrames * channels));
  Stats stats;
  int64_t total = 0;
  while (true) {
    const std::size_t old_size = audio.samples.size();
    audio.samples.resize(old_size + kBlockFrames);
    float* mono = audio.samples.data() + old_size;
    float* in = channels == 1 ? mono : block.data();
    const sf_count_t n = sf_readf_float(file.get(), in, kBlockFrames);
    if (n <= 0) {
      audio.samples.resize(old_size);
      break;
    }
    audio.samples.resize(old_size + static_cast<std::size_t>(n));
    KINEMO_RETURN_IF_ERROR(MixToMono(in, n, channels, info.samplerate, options.non_finite,
                                     total * channels, mono, stats, audio.non_finite_samples));
    total += n;
    if (total > max_frames) {
      return CheckAgainstLimits(info.samplerate, channels, total, options.limits);
    }
  }
  if (sf_error(file.get()) != SF_ERR_NO_ERROR) {
    return InvalidField("audio", kinemo::StrCat("decoding failed after ", total, " frames: ",
                                              sf_strerror(file.get())));
  }
  if (frames_exact && total < info.frames && !options.allow_truncated) {
    return InvalidField(audio.format,
                        kinemo::StrCat("truncated: header declares ", info.frames, " frames, only ",
                                     total, " decoded; set DecodeOptions::allow_truncated to read "
                                            "what is there"));
  }
  if (total == 0 && !options.allow_empty) {
    return InvalidField("audio.frames", "no samples (0 frames of ", audio.format, "/",
                        audio.subtype, "); set DecodeOptions::allow_empty to accept empty input");
  }
  audio.samples.shrink_to_fit();
  audio.duration_s = static_cast<double>(total) / info.samplerate;
  FinishStats(stats, audio);
  return audio;
}

StatusOr<DecodedAudio> DecodeAudio(std::string_view bytes, const DecodeOptions& options) {
  return DecodeAudio(AsBytes(bytes), options);
}

StatusOr<std::vector<std::uint8_t>> ReadFileBytes(const std::string& path, std::size_t max_bytes) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) {
    return absl::NotFoundError(kinemo::StrCat(path, ": no such file"));
  }
  if (!std::filesystem::is_regular_file(status)) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": not a regular file"));
  }
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return absl::InvalidArgumentError(kinemo::StrCat(path, ": ", ec.message()));
  if (size > max_bytes) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": audio.bytes: ", size,
                                                   " bytes exceed the limit of ", max_bytes,
                                                   " bytes (limits.max_bytes)"));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::PermissionDeniedError(kinemo::StrCat(path, ": cannot open for reading"));
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
  if (in.gcount() != static_cast<std::streamsize>(size)) {
    return absl::DataLossError(kinemo::StrCat(path, ": read ", in.gcount(), " of ", size, " bytes"));
  }
  return bytes;
}

StatusOr<DecodedAudio> DecodeAudioFile(const std::string& path, const DecodeOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateLimits(options.limits));
  KINEMO_ASSIGN_OR_RETURN(auto bytes, ReadFileBytes(path, options.limits.max_bytes));
  auto audio = DecodeAudio(std::span<const std::uint8_t>(bytes), options);
  if (!audio.ok()) return Annotate(audio.status(), path);
  return audio;
}

std::vector<std::string> SupportedFormats() {
  std::vector<std::string> lines;
  int count = 0;
  sf_command(nullptr, SFC_GET_FORMAT_MAJOR_COUNT, &count, sizeof(count));
  for (int i = 0; i < count; ++i) {
    SF_FORMAT_INFO info{};
    info.format = i;
    if (sf_command(nullptr, SFC_GET_FORMAT_MAJOR, &info, sizeof(info)) != 0) continue;
    lines.push_back(kinemo::StrCat(internal::MajorFormatName(info.format), ": ",
                                 info.name != nullptr ? info.name : "?"));
  }
  return lines;
}

// ---------------------------------------------------------------------------
// Headerless PCM.
// ---------------------------------------------------------------------------

StatusOr<PcmEncoding> ParsePcmEncoding(std::string_view name) {
  for (PcmEncoding e : {PcmEncoding::kS16Le, PcmEncoding::kS24Le, PcmEncoding::kS32Le,
                        PcmEncoding::kF32Le, PcmEncoding::kF64Le, PcmEncoding::kU8}) {
    if (name == PcmEncodingName(e)) return e;
  }
  return InvalidField("raw.encoding", "'", name,
                      "' is not supported (s16le, s24le, s32le, f32le, f64le, u8)");
}

std::string_view PcmEncodingName(PcmEncoding encoding) {
  switch (encoding) {
    case PcmEncoding::kS16Le: return "s16le";
    case PcmEncoding::kS24Le: return "s24le";
    case PcmEncoding::kS32Le: return "s32le";
    case PcmEncoding::kF32Le: return "f32le";
    case PcmEncoding::kF64Le: return "f64le";
    case PcmEncoding::kU8: return "u8";
  }
  return "?";
}

int BytesPerSample(PcmEncoding encoding) {
  switch (encoding) {
    case PcmEncoding::kS16Le: return 2;
    case PcmEncoding::kS24Le: return 3;
    case PcmEncoding::kS32Le: return 4;
    case PcmEncoding::kF32Le: return 4;
    case PcmEncoding::kF64Le: return 8;
    case PcmEncoding::kU8: return 1;
  }
  return 1;
}

Status AppendPcmAsMono(std::span<const std::uint8_t> bytes, PcmEncoding encoding, int channels,
                       NonFinitePolicy non_finite, std::vector<float>& out,
                       int64_t* non_finite_count) {
  return AppendPcmImpl(bytes, encoding, channels, 0, non_finite, out, non_finite_count, nullptr);
}

StatusOr<DecodedAudio> DecodeRawPcm(std::span<const std::uint8_t> bytes, const RawPcmFormat& format,
                                    const DecodeOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateLimits(options.limits));
  KINEMO_RETURN_IF_ERROR(CheckSize(bytes.size(), options));
  const int64_t frame_bytes = static_cast<int64_t>(BytesPerSample(format.encoding)) *
                              std::max(format.channels, 1);
  KINEMO_RETURN_IF_ERROR(CheckAgainstLimits(format.sample_rate_hz, format.channels,
                                            static_cast<int64_t>(bytes.size()) / frame_bytes,
                                            options.limits));
  if (bytes.empty() && !options.allow_empty) {
    return InvalidField("audio.bytes",
                        "empty input (0 bytes); set DecodeOptions::allow_empty to accept it");
  }
  DecodedAudio audio;
  audio.format = "raw";
  audio.subtype = std::string(PcmEncodingName(format.encoding));
  audio.format_description = "RAW (header-less)";
  audio.subtype_description = kinemo::StrCat("headerless PCM ", audio.subtype);
  audio.sample_rate_hz = format.sample_rate_hz;
  audio.channels = format.channels;
  Stats stats;
  KINEMO_RETURN_IF_ERROR(AppendPcmImpl(bytes, format.encoding, format.channels,
                                       format.sample_rate_hz, options.non_finite, audio.samples,
                                       &audio.non_finite_samples, &stats));
  audio.duration_s = static_cast<double>(audio.samples.size()) / format.sample_rate_hz;
  FinishStats(stats, audio);
  return audio;
}

StatusOr<DecodedAudio> DecodeRawPcm(std::string_view bytes, const RawPcmFormat& format,
                                    const DecodeOptions& options) {
  return DecodeRawPcm(AsBytes(bytes), format, options);
}

StatusOr<DecodedAudio> DecodeRawPcmFile(const std::string& path, const RawPcmFormat& format,
                                        const DecodeOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateLimits(options.limits));
  KINEMO_ASSIGN_OR_RETURN(auto bytes, ReadFileBytes(path, options.limits.max_bytes));
  auto audio = DecodeRawPcm(std::span<const std::uint8_t>(bytes), format, options);
  if (!audio.ok()) return Annotate(audio.status(), path);
  return audio;
}

}  // namespace kinemo::audio
