// Fuzzes the cube model (services/cube_tracker/core/cube_model.cc): the text
// proto of a cube file (`kinemo cube push`, the tracker's options and store)
// and the same bytes as the binary CubeModel of a ConfigureCube request. An
// accepted model must print and parse back to itself and draw its faces.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "services/cube_tracker/core/cube_model.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

using kinemo::cube::CubeModel;

bool SameModel(const CubeModel& a, const CubeModel& b) {
  if (a.name != b.name || a.dictionary != b.dictionary || a.cube_size_m != b.cube_size_m ||
      a.marker_size_m != b.marker_size_m) {
    return false;
  }
  for (int f = 0; f < kinemo::cube::kNumFaces; ++f) {
    if (a.faces[f].marker_id != b.faces[f].marker_id || a.faces[f].action != b.faces[f].action)
      return false;
  }
  return true;
}

void CheckAccepted(const CubeModel& model) {
  KINEMO_FUZZ_CHECK(kinemo::cube::ValidateCubeModel(model).ok(),
                    "an accepted model does not validate");
  auto again = kinemo::cube::ParseCubeModel(kinemo::cube::FormatCubeModel(model), "formatted");
  KINEMO_FUZZ_CHECK(again.ok(), again.status().ToString());
  KINEMO_FUZZ_CHECK(SameModel(model, *again), "format → parse changed the model");
  for (int f = 0; f < kinemo::cube::kNumFaces; ++f) {
    // A marker tiny against its face cannot be drawn at 48 px: that is the
    // caller's error (INVALID_ARGUMENT naming `pixels`), never OpenCV's.
    auto texture = kinemo::cube::RenderFaceTexture(model, f, 48);
    KINEMO_FUZZ_CHECK(
        texture.ok() || (texture.status().code() == absl::StatusCode::kInvalidArgument &&
                         texture.status().message().rfind("pixels:", 0) == 0),
        texture.status().ToString());
    (void)kinemo::cube::MarkerCorners(model, f);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text = kinemo::fuzz::Text(data, size);
  auto model = kinemo::cube::ParseCubeModel(text, "fuzz.cube");
  if (model.ok()) {
    CheckAccepted(*model);
  } else {
    KINEMO_FUZZ_CHECK_REFUSED(model.status(), absl::StatusCode::kInvalidArgument);
  }

  kinemo::cube_tracker::v1::CubeModel proto;
  if (proto.ParseFromArray(data, static_cast<int>(size))) {
    auto from_proto = kinemo::cube::CubeModelFromProto(proto);
    if (from_proto.ok()) {
      CheckAccepted(*from_proto);
    } else {
      KINEMO_FUZZ_CHECK_REFUSED(from_proto.status(), absl::StatusCode::kInvalidArgument);
    }
  }
  return 0;
}
