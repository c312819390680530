// Internal: libsndfile virtual I/O over memory, and format naming.
// Not part of kinemo_audio's public API.
#pragma once

#include <sndfile.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/status/status.h"

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

// Reads n bytes at pos into out; false if they are not all there.
using ReadAt = std::function<bool(std::uint64_t pos, std::uint8_t* out, std::size_t n)>;

// How a RIFF/WAVE input is cut short (libsndfile reads what is there
// without a word): its data chunk declares more bytes than are present, or
// it ends inside a chunk header before any data chunk.
struct RiffDamage {
  bool truncated_data = false;  // else: a truncated chunk header
  std::uint64_t declared = 0;   // data bytes the header declares
  std::uint64_t offset = 0;     // where the data (or the cut header) starts
  std::uint64_t available = 0;  // bytes present from there
};
// For an input of `size` bytes: the damage, if it is a RIFF/WAVE input cut
// short; nullopt otherwise (other inputs too).
std::optional<RiffDamage> FindRiffDamage(std::uint64_t size, const ReadAt& read);

}  // namespace kinemo::audio::internal
