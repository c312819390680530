#include "common/audio/recording_writer.h"

#include <sndfile.h>

#include <filesystem>

namespace kinemo::audio {

struct RecordingWriter::Impl {
  SNDFILE* file = nullptr;
  ~Impl() {
    if (file != nullptr) sf_close(file);
  }
};

RecordingWriter::~RecordingWriter() = default;

StatusOr<std::unique_ptr<RecordingWriter>> RecordingWriter::Create(const std::string& path, int sample_rate_hz,
                                                                   int channels) {
  const std::string ext = std::filesystem::path(path).extension().string();
  int format = 0;
  if (ext == ".wav") {
    format = SF_FORMAT_WAV | SF_FORMAT_PCM_16;
  } else if (ext == ".flac") {
    format = SF_FORMAT_FLAC | SF_FORMAT_PCM_16;
  } else if (ext == ".ogg") {
    format = SF_FORMAT_OGG | SF_FORMAT_VORBIS;
  } else if (ext == ".mp3") {
    format = SF_FORMAT_MPEG | SF_FORMAT_MPEG_LAYER_III;
  } else {
    return InvalidField("path", path, ": write .wav, .flac, .ogg or .mp3");
  }
  SF_INFO info{};
  info.samplerate = sample_rate_hz;
  info.channels = channels;
  info.format = format;
  if (!sf_format_check(&info)) {
    return InvalidField("path", path, ": ", ext, " cannot hold ", channels, " channels at ", sample_rate_hz, " Hz");
  }
  std::unique_ptr<RecordingWriter> w(new RecordingWriter());
  w->impl_ = std::make_unique<Impl>();
  w->path_ = path;
  w->channels_ = channels;
  w->impl_->file = sf_open(path.c_str(), SFM_WRITE, &info);
  if (w->impl_->file == nullptr) {
    return absl::UnavailableError(kinemo::StrCat(path, ": cannot write: ", sf_strerror(nullptr)));
  }
  return w;
}

Status RecordingWriter::Write(std::span<const float> interleaved) {
  if (impl_->file == nullptr) return absl::FailedPreconditionError(kinemo::StrCat(path_, ": closed"));
  if (interleaved.size() % static_cast<std::size_t>(channels_) != 0) {
    return InvalidField("interleaved", interleaved.size(), " samples is not a whole number of frames");
  }
  const sf_count_t frames = static_cast<sf_count_t>(interleaved.size()) / channels_;
  if (sf_writef_float(impl_->file, interleaved.data(), frames) != frames) {
    return absl::UnavailableError(kinemo::StrCat(path_, ": write failed: ", sf_strerror(impl_->file)));
  }
  return absl::OkStatus();
}

Status RecordingWriter::Close() {
  if (impl_->file == nullptr) return absl::OkStatus();
  const int rc = sf_close(impl_->file);
  impl_->file = nullptr;
  if (rc != 0) return absl::UnavailableError(kinemo::StrCat(path_, ": cannot finish the file"));
  return absl::OkStatus();
}

}  // namespace kinemo::audio
