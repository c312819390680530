// A small PNG encoder (8-bit gray, RGB or RGBA; zlib deflate), so that tools
// which only draw plots and previews need not load OpenCV's imgcodecs (which
// on Debian pulls in GDAL and ~140 shared libraries, 0.3 s of start-up).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "common/status/status.h"

namespace kinemo::image {

struct PixelBuffer {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  int channels = 3;         // 1 gray, 3 colour, 4 colour + alpha
  std::size_t stride = 0;   // bytes per row; 0 = width × channels
  bool bgr = true;          // colour order of 3/4-channel data (OpenCV's is BGR)
};

// The PNG file's bytes. INVALID_ARGUMENT for an empty image, a null buffer,
// channels other than 1/3/4, or a stride shorter than a row.
StatusOr<std::string> EncodePng(const PixelBuffer& pixels, int compression_level = 6);

// Encodes and writes atomically (temporary file, then rename).
Status WritePngFile(const std::string& path, const PixelBuffer& pixels, int compression_level = 6);

}  // namespace kinemo::image
