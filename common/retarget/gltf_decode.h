// Compressed glTF in, plain glTF out: the one place where kinemo decodes
// EXT_meshopt_compression (Debian's libmeshoptimizer: the vertex, index and
// index-sequence codecs and the octahedral / quaternion / exponential
// filters) and KHR_draco_mesh_compression (Debian's libdraco), so that every
// reader of a character (retarget, rig push, animate --rig, the studio's
// server side, the AR view) gets plain buffer views from tinygltf.
//
// What comes out is the same document with:
// - every meshopt-compressed bufferView replaced by its decoded bytes (the
//   view keeps its index, byteStride and target), and fallback buffers gone;
// - every Draco-compressed primitive's accessors given bufferViews of their
//   own (appended) holding the decoded values in the accessor's component
//   type (vertex attributes 4-byte aligned, as the glTF specification asks);
// - one buffer (the GLB's BIN chunk) holding every view;
// - the two extensions removed from extensionsUsed / extensionsRequired.
// KHR_mesh_quantization (integer / normalized attributes: the accessors say
// so) and image formats such as EXT_texture_webp are left as they are: the
// images' bytes pass through untouched.
//
// Every size comes from the file, so every one is bounded before it is used:
// chunk lengths against the bytes present, views and ranges against their
// buffers, count × stride against overflow and against
// GltfDecodeLimits::max_decoded_bytes. A hostile or damaged file is refused
// with INVALID_ARGUMENT naming the file and the part:
//   "man.glb: bufferViews[6].extensions.EXT_meshopt_compression: ..."
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::retarget {

struct GltfDecodeLimits {
  // The sum of all decoded buffer views (meshopt and Draco), bytes.
  std::uint64_t max_decoded_bytes = std::uint64_t{1} << 30;
  // The JSON chunk / .gltf text, bytes, and how deep its arrays and objects nest.
  std::uint64_t max_json_bytes = std::uint64_t{64} << 20;
  int max_json_depth = 64;
};

// The extensions this module decodes.
inline constexpr std::string_view kMeshoptExtension = "EXT_meshopt_compression";
inline constexpr std::string_view kDracoExtension = "KHR_draco_mesh_compression";

struct DecodedGlb {
  std::string glb;                      // a plain GLB (one buffer: its BIN chunk)
  std::vector<std::string> decoded;     // the compression extensions it used
};

// A GLB held in memory. std::nullopt when it uses neither compression
// extension (the caller reads the bytes as they are). `base_dir` resolves
// buffers given by relative uri ("" = such buffers are refused).
StatusOr<std::optional<DecodedGlb>> DecodeCompressedGlb(std::string_view glb, const std::string& name,
                                                        const std::string& base_dir = "",
                                                        const GltfDecodeLimits& limits = {});

// A .gltf (JSON text) whose buffers are data: URIs or files relative to
// `base_dir`; the result is a GLB. std::nullopt as above.
StatusOr<std::optional<DecodedGlb>> DecodeCompressedGltf(std::string_view json_text, const std::string& name,
                                                         const std::string& base_dir,
                                                         const GltfDecodeLimits& limits = {});

// How deep JSON text nests (arrays and objects; strings skipped), stopping
// once past `limit`. Used before parsing outside JSON.
int JsonNestingDepth(std::string_view text, int limit);

}  // namespace kinemo::retarget
