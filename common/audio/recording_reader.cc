#include "common/audio/recording_reader.h"

#include <fcntl.h>
#include <sndfile.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>

#include "absl/strings/str_format.h"
#include "common/audio/resample.h"
#include "common/audio/sndfile_memory.h"

namespace kinemo::audio {
namespace {

constexpr std::int64_t kMaxBlockFrames = 1 << 16;

// The first bytes of a file, printable, for "it starts with '...'".
std::string FirstBytes(int fd) {
  unsigned char head[4] = {};
  const ssize_t n = ::pread(fd, head, sizeof(head), 0);
  std::string out;
  for (ssize_t i = 0; i < n; ++i) {
    out += std::isprint(head[i]) ? std::string(1, static_cast<char>(head[i])) : absl::StrFormat("\\x%02x", head[i]);
  }
  return out;
}

}  // namespace

struct RecordingReader::Impl {
  int fd = -1;
  SNDFILE* file = nullptr;
  std::unique_ptr<StreamingResampler> resampler;
  ~Impl() {
    if (file != nullptr) sf_close(file);
    if (fd >= 0) ::close(fd);
  }
};

RecordingReader::~RecordingReader() = default;

Status RecordingReader::Error(std::string_view message) const {
  return absl::InvalidArgumentError(kinemo::StrCat(path_, ": ", message));
}

StatusOr<std::unique_ptr<RecordingReader>> RecordingReader::Open(const std::string& path, int out_rate_hz,
                                                                 const DecodeOptions& options) {
  KINEMO_RETURN_IF_ERROR(ValidateLimits(options.limits));
  if (out_rate_hz <= 0) return InvalidField("out_rate_hz", out_rate_hz, " must be > 0");
  std::unique_ptr<RecordingReader> r(new RecordingReader());
  r->path_ = path;
  r->out_rate_hz_ = out_rate_hz;
  r->options_ = options;
  r->impl_ = std::make_unique<Impl>();
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) return absl::NotFoundError(kinemo::StrCat(path, ": no such file"));
  if (std::filesystem::is_directory(status)) return r->Error("is a folder, not an audio file");
  if (!std::filesystem::is_regular_file(status)) return r->Error("not a regular file");
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return r->Error(ec.message());
  r->info_.file_bytes = static_cast<std::int64_t>(size);
  if (size == 0) return r->Error("empty file (0 bytes): there is no recording in it");
  r->impl_->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (r->impl_->fd < 0) {
    return absl::PermissionDeniedError(kinemo::StrCat(path, ": cannot open for reading: ", std::strerror(errno)));
  }
  const int fd = r->impl_->fd;
  if (!options.allow_truncated) {
    const auto damage = internal::FindRiffDamage(size, [fd](std::uint64_t pos, std::uint8_t* out, std::size_t n) {
      return ::pread(fd, out, n, static_cast<off_t>(pos)) == static_cast<ssize_t>(n);
    });
    if (damage && damage->truncated_data) {
      return r->Error(kinemo::StrCat("truncated WAV: the header declares ", damage->declared, " bytes of audio, ",
                                     damage->available, " are there (the file was cut short: copy or export it again)"));
    }
    if (damage) return r->Error("truncated WAV: it ends inside its header (the file was cut short: copy or export it again)");
  }
  const std::string first_bytes = FirstBytes(fd);
  SF_INFO info{};
  r->impl_->file = sf_open_fd(fd, SFM_READ, &info, /*close_desc=*/SF_FALSE);
  if (r->impl_->file == nullptr) {
    return r->Error(kinemo::StrCat("not an audio file that can be read (it starts with '", first_bytes,
                                   "'; ", sf_strerror(nullptr), "); ", kRecordingFormatsText, " can"));
  }
  RecordingInfo& ri = r->info_;
  ri.format = internal::MajorFormatName(info.format);
  ri.subtype = internal::SubtypeName(info.format);
  ri.format_description = internal::MajorFormatDescription(info.format);
  ri.sample_rate_hz = info.samplerate;
  ri.channels = info.channels;
  ri.frames = info.frames;
  ri.duration_s = info.samplerate > 0 ? static_cast<double>(info.frames) / info.samplerate : 0;
  if (std::find(options.accepted_formats.begin(), options.accepted_formats.end(), ri.format) ==
      options.accepted_formats.end()) {
    return r->Error(kinemo::StrCat(ri.format_description, " is not a format kinemo reads; convert it to one of ",
                                   kRecordingFormatsText));
  }
  if (Status s = CheckAgainstLimits(info.samplerate, info.channels, info.frames, options.limits); !s.ok()) {
    if (info.samplerate > 0 && info.frames >= 0 &&
        static_cast<double>(info.frames) / info.samplerate > options.limits.max_duration_s) {
      return r->Error(absl::StrFormat("%.0f s of audio is longer than the %g s this accepts; split the recording",
                                      ri.duration_s, options.limits.max_duration_s));
    }
    return r->Error(std::string(s.message()));
  }
  if (info.frames == 0) return r->Error(kinemo::StrCat("no audio in it (0 frames of ", ri.format_description, ")"));
  KINEMO_ASSIGN_OR_RETURN(StreamingResampler resampler, StreamingResampler::Create(info.samplerate, out_rate_hz));
  r->impl_->resampler = std::make_unique<StreamingResampler>(std::move(resampler));
  return r;
}

StatusOr<bool> RecordingReader::Read(std::int64_t max_in_frames, std::vector<float>* out) {
  if (finished_) return false;
  const int channels = info_.channels;
  const std::int64_t want = std::clamp<std::int64_t>(max_in_frames, 1, kMaxBlockFrames);
  block_.resize(static_cast<std::size_t>(want * channels));
  const sf_count_t n = sf_readf_float(impl_->file, block_.data(), want);
  if (n <= 0) {
    if (sf_error(impl_->file) != SF_ERR_NO_ERROR) {
      return Error(kinemo::StrCat("cannot decode past ", absl::StrFormat("%.2f", seconds_read()),
                                  " s: ", sf_strerror(impl_->file)));
    }
    if (frames_read_ == 0) return Error(kinemo::StrCat("no audio in it (0 frames of ", info_.format_description, ")"));
    KINEMO_RETURN_IF_ERROR(impl_->resampler->Flush(*out));
    finished_ = true;
    return true;
  }
  mono_.resize(static_cast<std::size_t>(n));
  for (sf_count_t f = 0; f < n; ++f) {
    double sum = 0;
    for (int c = 0; c < channels; ++c) {
      const float x = block_[static_cast<std::size_t>(f * channels + c)];
      if (!std::isfinite(x)) {
        return Error(absl::StrFormat("sample %d (t=%.3f s) is not a number: the file is damaged",
                                     frames_read_ + f, static_cast<double>(frames_read_ + f) / info_.sample_rate_hz));
      }
      sum += x;
    }
    mono_[static_cast<std::size_t>(f)] = static_cast<float>(channels == 1 ? sum : sum / channels);
  }
  frames_read_ += n;
  if (seconds_read() > options_.limits.max_duration_s) {
    return Error(absl::StrFormat("more than the %g s of audio this accepts; split the recording",
                                 options_.limits.max_duration_s));
  }
  KINEMO_RETURN_IF_ERROR(impl_->resampler->Process(mono_, *out));
  return true;
}

}  // namespace kinemo::audio
