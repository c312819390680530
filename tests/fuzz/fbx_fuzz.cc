// Fuzzes the FBX character reader (common/retarget/fbx.h): the bytes of a
// .fbx as `kinemo retarget --to`, `animate --rig` and `rig info` read it
// (ReadFbxFromMemory: the structure check of what assimp trusts, assimp's
// FBX importer, the conversion into a glTF document), then what every
// reader does with the document: the rig (skin, bind space, role map), the
// face map (morph targets from blend shapes), the rig info, the skinned
// mesh. Properties: refusals are INVALID_ARGUMENT (FAILED_PRECONDITION for
// no skinned triangles) starting with the file's name; an accepted rig's
// rest positions are finite; face weights stay in [0, 1]. assimp itself is
// not instrumented (Debian's library): a crash inside it is still a crash.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "common/retarget/face_map.h"
#include "common/retarget/fbx.h"
#include "common/retarget/mesh.h"
#include "common/retarget/rig.h"
#include "common/retarget/rig_info.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

using namespace kinemo::retarget;

// Small enough for the fuzzer's 1 GiB malloc limit, large enough for the seeds.
FbxLimits Limits() {
  FbxLimits l;
  l.max_bytes = 16 << 20;
  l.max_vertices = 1 << 20;
  l.max_nodes = 4096;
  return l;
}

void CheckNamed(const absl::Status& s, std::string_view name) {
  const std::string message(s.message());
  KINEMO_FUZZ_CHECK(message.rfind(name, 0) == 0, s.ToString());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes = kinemo::fuzz::Text(data, size);
  auto src = ReadFbxFromMemory(bytes, "fuzz.fbx", Limits());
  if (!src.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(src.status(), absl::StatusCode::kInvalidArgument);
    CheckNamed(src.status(), "fuzz.fbx: ");
    return 0;
  }
  KINEMO_FUZZ_CHECK((*src)->format == "fbx", "not marked as FBX");
  auto rig = RigFromGltf(*src);
  if (!rig.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(rig.status(), absl::StatusCode::kInvalidArgument);
    CheckNamed(rig.status(), "fuzz.fbx");
    return 0;
  }
  for (const auto& p : rig->RestPositions()) KINEMO_FUZZ_CHECK(p.allFinite(), "a rest position is not finite");
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
