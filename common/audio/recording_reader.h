// A recording read from its file block by block, mixed to mono and
// resampled to one rate: audio of any length with bounded memory (an hour
// of 44.1 kHz stereo WAV is 635 MB on disk; the reader holds one block).
// The client side of the chunked RPCs (`kinemo animate` sends 16 kHz mono,
// what the prosody analysis runs at, whatever the file's rate and channels).
//
// The same containers and checks as DecodeAudio (audio.h): WAV, WAVEX, RF64,
// W64, AIFF, FLAC, OGG (Vorbis, Opus) and MP3; a WAV whose data chunk is cut
// short and a non-finite sample are errors; mono by averaging the channels;
// libsoxr's resampling as Resample() (the same samples, up to float
// rounding). Messages start with the file's path and say what the user can
// do about it, e.g.
//   "talk.wav: empty file (0 bytes)"
//   "notes.wav: not an audio file that can be read (it starts with 'Dear'); WAV, FLAC, OGG (Vorbis, Opus), MP3 and
//    AIFF can"
//   "cut.wav: truncated WAV: the header declares 2646000 bytes of audio, 1000000 are there (the file was cut short:
//    copy or export it again)"
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/audio/audio.h"
#include "common/status/status.h"

namespace kinemo::audio {

// The containers a recording may come in, for messages and --help:
// "WAV, FLAC, OGG (Vorbis, Opus), MP3 and AIFF".
inline constexpr const char* kRecordingFormatsText = "WAV, FLAC, OGG (Vorbis, Opus), MP3 and AIFF";

// What the file's header says.
struct RecordingInfo {
  std::string format;              // short container name: "wav", "mpeg", ...
  std::string subtype;             // "pcm_16", "vorbis", "mpeg_layer_iii", ...
  std::string format_description;  // libsndfile's, e.g. "WAV (Microsoft)"
  int sample_rate_hz = 0;          // the file's rate
  int channels = 0;                // the file's channels
  std::int64_t frames = 0;         // sample frames the header declares (MP3: the decoder's estimate)
  double duration_s = 0;           // frames / sample_rate_hz
  std::int64_t file_bytes = 0;     // the file's size
};

class RecordingReader {
 public:
  // Opens `path` for reading at `out_rate_hz` (> 0). `options.limits`
  // bounds the rate, channels and duration (its max_bytes does not apply:
  // the file is never held whole). Errors: NOT_FOUND (no such file),
  // INVALID_ARGUMENT (not a regular file, empty, not audio, truncated WAV,
  // a container outside options.accepted_formats, over a limit),
  // PERMISSION_DENIED (cannot be opened).
  static StatusOr<std::unique_ptr<RecordingReader>> Open(const std::string& path, int out_rate_hz,
                                                         const DecodeOptions& options = {});
  ~RecordingReader();

  const RecordingInfo& info() const { return info_; }
  int out_rate_hz() const { return out_rate_hz_; }

  // Appends the next samples at out_rate_hz (from up to `max_in_frames` of
  // the file's frames) to `out`. False once the file and the resampler's
  // tail are all read (nothing appended then). Errors (the path first): a
  // non-finite sample, a decoding error, more audio than
  // limits.max_duration_s.
  StatusOr<bool> Read(std::int64_t max_in_frames, std::vector<float>* out);

  // The file's frames read so far, and their duration in seconds.
  std::int64_t frames_read() const { return frames_read_; }
  double seconds_read() const { return static_cast<double>(frames_read_) / info_.sample_rate_hz; }

 private:
  struct Impl;
  RecordingReader() = default;
  Status Error(std::string_view message) const;

  std::unique_ptr<Impl> impl_;
  std::string path_;
  RecordingInfo info_;
  int out_rate_hz_ = 0;
  DecodeOptions options_;
  std::int64_t frames_read_ = 0;
  bool finished_ = false;
  std::vector<float> block_;  // interleaved frames of the file
  std::vector<float> mono_;   // mixed to mono
};

}  // namespace kinemo::audio
