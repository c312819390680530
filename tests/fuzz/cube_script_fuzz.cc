// Fuzzes cube scripts (services/cube_tracker/render: the JSON that `kinemo
// cube render` and the Vleo demo read): ParseRenderScript, then what the
// renderer derives from an accepted script before drawing (duration, frame
// count).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "services/cube_tracker/render/renderer.h"
#include "tests/fuzz/fuzz_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto script = kinemo::cube::ParseRenderScript(text, "/scripts");
  if (!script.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(script.status(), absl::StatusCode::kInvalidArgument);
    return 0;
  }
  KINEMO_FUZZ_CHECK(!script->keys.empty(), "a script without keys");
  KINEMO_FUZZ_CHECK(std::isfinite(script->duration_s()) && script->duration_s() >= 0,
                    "duration not finite");
  KINEMO_FUZZ_CHECK(script->frame_count() >= 1, "no frames");
  for (const auto& key : script->keys) {
    for (double v : {key.t_s, key.x_m, key.y_m, key.lift_m, key.yaw_deg, key.roll_x_deg,
                     key.roll_y_deg, key.hand, key.light, key.blur_px}) {
      KINEMO_FUZZ_CHECK(std::isfinite(v), "a key value is not finite");
    }
  }
  return 0;
}
