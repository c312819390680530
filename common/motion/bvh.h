// BVH (Biovision Hierarchy) reader and writer.
//
// Reader: any channel order, 0/3/6-channel joints (position channels on any
// joint), End Sites, any frame time, tabs / CRLF / extra whitespace. Numbers
// are parsed with std::from_chars straight into the frame matrix. Every
// malformed input gives an INVALID_ARGUMENT status whose message starts with
// "<name>:<line>:"; limits (file size, joints, frames, values) are enforced
// and named in the message. One frame per line, as BVH writers produce.
//
// Writer: the same hierarchy (joint names, channel order, offsets, end sites)
// and the motion; by default numbers are written in the shortest form that
// reads back to the identical double (std::to_chars), so a round trip is
// exact.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::motion {

// How a joint's position channels relate to its OFFSET (see Joint).
enum class PositionChannels {
  kAuto,     // per joint: relative when, on every axis where the OFFSET is
             // significant (>= 10 % of its largest component), the channels'
             // mean is nearer 0 than the OFFSET value, else absolute
  kReplace,  // channels are the local translation (OFFSET ignored)
  kAdd,      // channels are added to OFFSET
};

struct BvhReadOptions {
  PositionChannels position_channels = PositionChannels::kAuto;
  int64_t max_file_bytes = int64_t{1} << 30;  // 1 GiB
  int max_joints = 1024;
  int64_t max_frames = 10'000'000;
  int64_t max_values = 250'000'000;  // frames × channels (2 GB of doubles)
  int max_nesting_depth = 256;
};

// Parses BVH text. `name` (usually the file name) prefixes error messages.
StatusOr<Clip> ParseBvh(std::string_view text, std::string_view name,
                        const BvhReadOptions& options = {});

// Reads and parses a BVH file.
StatusOr<Clip> ReadBvhFile(const std::string& path, const BvhReadOptions& options = {});

struct BvhWriteOptions {
  // 0: shortest representation that round-trips exactly; otherwise that many
  // significant digits (e.g. 9 gives ≤ 1e-8 relative error, smaller files).
  int significant_digits = 0;
  std::string_view indent = "\t";
};

// Serialises a clip (the clip must pass Clip::Validate()).
StatusOr<std::string> WriteBvh(const Clip& clip, const BvhWriteOptions& options = {});

// BVH text in pieces, for motion too large to hold as one string (a long
// recording's motion sent as messages, or written to a file as it is made):
// the pieces concatenated are exactly WriteBvh's text. The clip must outlive
// the writer and not change while it is used.
class BvhTextWriter {
 public:
  // Errors as WriteBvh.
  static StatusOr<BvhTextWriter> Create(const Clip& clip, const BvhWriteOptions& options = {});

  // Appends the next piece to `out`: the header (HIERARCHY, MOTION, Frames,
  // Frame Time) first, then whole frame lines until the piece holds at least
  // `max_bytes` or the frames end. False (nothing appended) once everything
  // was written.
  bool Next(std::size_t max_bytes, std::string* out);
  // True once everything was written.
  bool done() const { return header_written_ && next_frame_ >= clip_->num_frames(); }
  // Frames written so far.
  int frames_written() const { return next_frame_; }

 private:
  BvhTextWriter(const Clip* clip, int significant_digits) : clip_(clip), significant_digits_(significant_digits) {}
  void AppendFrame(int f, std::string* out) const;

  const Clip* clip_;
  int significant_digits_;
  std::string header_;
  std::vector<int> columns_;  // channel columns in file order
  bool header_written_ = false;
  int next_frame_ = 0;
};

// Writes a clip to a file (replaced atomically via a temporary file).
Status WriteBvhFile(const Clip& clip, const std::string& path, const BvhWriteOptions& options = {});

}  // namespace kinemo::motion
