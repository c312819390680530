// Fuzzes the character readers (common/retarget): a GLB as an upload or a
// pushed rig arrives (ReadGlbFromMemory: the GLB container, the
// EXT_meshopt_compression / KHR_draco_mesh_compression decoders of
// gltf_decode.h, then tinygltf), and what every reader then does with it:
// the rig (skin or VRM humanoid, bind space, role map), the face map (morph
// targets, VRM 0.x / 1.0 expressions and their binds), the rig info, the
// skinned mesh (quantized accessors). Inputs that start with '{' go to the
// .gltf JSON decoder instead. Properties: refusals are INVALID_ARGUMENT (or
// FAILED_PRECONDITION: no skinned triangles) with a message starting with
// the file's name; a decoded document is a GLB that tinygltf reads again;
// face weights stay in [0, 1].
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "common/retarget/face_map.h"
#include "common/retarget/gltf.h"
#include "common/retarget/gltf_decode.h"
#include "common/retarget/mesh.h"
#include "common/retarget/rig.h"
#include "common/retarget/rig_info.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

using namespace kinemo::retarget;

// Small enough for the fuzzer's 1 GiB malloc limit, large enough for the seeds.
GltfDecodeLimits Limits() {
  GltfDecodeLimits l;
  l.max_decoded_bytes = 64 << 20;
  return l;
}

void CheckNamed(const absl::Status& s, std::string_view name) {
  const std::string message(s.message());
  KINEMO_FUZZ_CHECK(message.rfind(name, 0) == 0, s.ToString());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes = kinemo::fuzz::Text(data, size);
  if (!bytes.empty() && bytes[0] == '{') {
    auto decoded = DecodeCompressedGltf(bytes, "fuzz.gltf", "/nonexistent-kinemo-fuzz", Limits());
    if (!decoded.ok()) {
      KINEMO_FUZZ_CHECK_REFUSED(decoded.status(), absl::StatusCode::kInvalidArgument);
      CheckNamed(decoded.status(), "fuzz.gltf: ");
    }
    return 0;
  }
  auto decoded = DecodeCompressedGlb(bytes, "fuzz.glb", "", Limits());
  if (!decoded.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(decoded.status(), absl::StatusCode::kInvalidArgument);
    CheckNamed(decoded.status(), "fuzz.glb: ");
  } else if (decoded->has_value()) {
    // What the decoder writes is a plain GLB: decoding it again finds nothing.
    auto again = DecodeCompressedGlb((*decoded)->glb, "decoded.glb", "", Limits());
    KINEMO_FUZZ_CHECK(again.ok() && !again->has_value(), again.ok() ? "decoded twice" : again.status().ToString());
  }
  auto src = ReadGlbFromMemory(bytes, "fuzz.glb", Limits());
  if (!src.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(src.status(), absl::StatusCode::kInvalidArgument);
    CheckNamed(src.status(), "fuzz.glb: ");
    return 0;
  }
  auto rig = RigFromGltf(*src);
  if (!rig.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(rig.status(), absl::StatusCode::kInvalidArgument);
    return 0;
  }
  auto face = FaceMap::Create(*rig);
  if (!face.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(face.status(), absl::StatusCode::kInvalidArgument);
    return 0;
  }
  (void)RigInfoJson(*rig, *face).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  kinemo::face::FaceFrame frame;
  frame.ovr[10] = 1;
  frame.jaw_open_deg = 12;
  frame.blink_left = 1;
  std::vector<float> weights(face->controls().size()), morphs(static_cast<size_t>(face->num_morph_weights()));
  face->Weights(frame, weights);
  face->MorphWeights(weights, morphs);
  for (float w : morphs) KINEMO_FUZZ_CHECK(w >= 0 && w <= 1, "a morph weight outside [0, 1]");
  auto mesh = LoadCharacterMesh(*rig);
  if (!mesh.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(mesh.status(), absl::StatusCode::kInvalidArgument,
                              absl::StatusCode::kFailedPrecondition);
  }
  return 0;
}
