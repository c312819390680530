// Internal: libsndfile virtual I/O over memory, and format naming.
// Not part of kinemo_audio's public API.
#pragma once

#include <sndfile.h>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace kinemo::audio::internal {

// A read-only, seekable view of a byte buffer for sf_open_virtual.
struct MemoryReader {
  const std::uint8_t* data = nullptr;
  sf_count_t size = 0;
  sf_count_t pos = 0;
};

// A growable, seekable byte buffer for sf_open_virtual in write mode.
struct MemoryWriter {
  std::vector<std::uint8_t>* bytes = nullptr;
  sf_count_t pos = 0;
};

SF_VIRTUAL_IO* ReaderIo();
SF_VIRTUAL_IO* WriterIo();

struct SndfileCloser {
  void operator()(SNDFILE* f) const {
    if (f != nullptr) sf_close(f);
  }
};
using SndfilePtr = std::unique_ptr<SNDFILE, SndfileCloser>;

// Short names: "wav", "flac", ... and "pcm_16", "float", ...
std::string MajorFormatName(int format);
std::string SubtypeName(int format);
// libsndfile's own descriptions ("WAV (Microsoft)", "Signed 16 bit PCM").
std::string MajorFormatDescription(int format);
std::string SubtypeDescription(int format);

}  // namespace kinemo::audio::internal
