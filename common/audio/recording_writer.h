// A recording written block by block to a file (WAV, FLAC, OGG Vorbis or
// MP3, by the file's extension) with libsndfile: long test and benchmark
// audio (an hour of 44.1 kHz stereo) made without holding it whole.
#pragma once

#include <memory>
#include <span>
#include <string>

#include "common/status/status.h"

namespace kinemo::audio {

class RecordingWriter {
 public:
  // `path` ending in .wav (16-bit PCM), .flac (16-bit), .ogg (Vorbis) or
  // .mp3 (MPEG layer III, as this libsndfile encodes it). INVALID_ARGUMENT
  // for another extension, a rate or channel count the format refuses;
  // UNAVAILABLE when the file cannot be created.
  static StatusOr<std::unique_ptr<RecordingWriter>> Create(const std::string& path, int sample_rate_hz,
                                                           int channels);
  ~RecordingWriter();

  // Appends interleaved frames (samples in [-1, 1]; a multiple of channels).
  Status Write(std::span<const float> interleaved);
  // Finishes the file (also done by the destructor, without a status).
  Status Close();

 private:
  struct Impl;
  RecordingWriter() = default;
  std::unique_ptr<Impl> impl_;
  std::string path_;
  int channels_ = 0;
};

}  // namespace kinemo::audio
