#include "common/image/png.h"

#include <zlib.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <vector>

namespace kinemo::image {
namespace {

void PutU32(std::string* out, std::uint32_t v) {
  out->push_back(static_cast<char>(v >> 24));
  out->push_back(static_cast<char>(v >> 16));
  out->push_back(static_cast<char>(v >> 8));
  out->push_back(static_cast<char>(v));
}

void PutChunk(std::string* out, const char type[4], const std::string& payload) {
  PutU32(out, static_cast<std::uint32_t>(payload.size()));
  const std::size_t start = out->size();
  out->append(type, 4);
  out->append(payload);
  const auto* bytes = reinterpret_cast<const Bytef*>(out->data() + start);
  PutU32(out, static_cast<std::uint32_t>(crc32(crc32(0L, Z_NULL, 0), bytes, static_cast<uInt>(out->size() - start))));
}

}  // namespace

StatusOr<std::string> EncodePng(const PixelBuffer& p, int compression_level) {
  if (p.data == nullptr) return InvalidField("pixels.data", "is null");
  if (p.width <= 0 || p.height <= 0) return InvalidField("pixels", "empty image ", p.width, "x", p.height);
  if (p.channels != 1 && p.channels != 3 && p.channels != 4) {
    return InvalidField("pixels.channels", p.channels, " (expected 1, 3 or 4)");
  }
  const std::size_t row = static_cast<std::size_t>(p.width) * static_cast<std::size_t>(p.channels);
  const std::size_t stride = p.stride == 0 ? row : p.stride;
  if (stride < row) return InvalidField("pixels.stride", stride, " is shorter than a row of ", row, " bytes");

  // Filter type 0 (none) per row; colour reordered to RGB(A).
  std::vector<std::uint8_t> raw((row + 1) * static_cast<std::size_t>(p.height));
  for (int y = 0; y < p.height; ++y) {
    std::uint8_t* dst = raw.data() + static_cast<std::size_t>(y) * (row + 1);
    const std::uint8_t* src = p.data + static_cast<std::size_t>(y) * stride;
    dst[0] = 0;
    if (p.channels == 1 || !p.bgr) {
      std::copy(src, src + row, dst + 1);
    } else {
      for (int x = 0; x < p.width; ++x) {
        const std::uint8_t* s = src + static_cast<std::size_t>(x) * static_cast<std::size_t>(p.channels);
        std::uint8_t* d = dst + 1 + static_cast<std::size_t>(x) * static_cast<std::size_t>(p.channels);
        d[0] = s[2];
        d[1] = s[1];
        d[2] = s[0];
        if (p.channels == 4) d[3] = s[3];
      }
    }
  }
  uLongf packed_size = compressBound(static_cast<uLong>(raw.size()));
  std::string packed(packed_size, '\0');
  if (compress2(reinterpret_cast<Bytef*>(packed.data()), &packed_size, raw.data(), static_cast<uLong>(raw.size()),
                compression_level) != Z_OK) {
    return absl::InternalError("png: zlib compression failed");
  }
  packed.resize(packed_size);

  std::string out("\x89PNG\r\n\x1a\n", 8);
  std::string ihdr;
  PutU32(&ihdr, static_cast<std::uint32_t>(p.width));
  PutU32(&ihdr, static_cast<std::uint32_t>(p.height));
  const char colour_type = p.channels == 1 ? 0 : (p.channels == 3 ? 2 : 6);
  ihdr += std::string{'\x08', colour_type, '\0', '\0', '\0'};  // depth 8, deflate, adaptive filter, no interlace
  PutChunk(&out, "IHDR", ihdr);
  PutChunk(&out, "IDAT", packed);
  PutChunk(&out, "IEND", "");
  return out;
}

Status WritePngFile(const std::string& path, const PixelBuffer& pixels, int compression_level) {
  KINEMO_ASSIGN_OR_RETURN(std::string bytes, EncodePng(pixels, compression_level));
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return absl::PermissionDeniedError(kinemo::StrCat(path, ": cannot write"));
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) return absl::InternalError(kinemo::StrCat(path, ": write failed"));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return absl::InternalError(kinemo::StrCat(path, ": ", ec.message()));
  return absl::OkStatus();
}

}  // namespace kinemo::image
