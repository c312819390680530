// Fuzzes the viseme file's reader (common/face FaceTrackFromJson): `kinemo
// retarget --visemes V.json` reads files users bring. Refusals are
// INVALID_ARGUMENT naming the file; accepted tracks have every channel in
// range and write and read back to the same frames (FaceTrackToJson rounds to
// 4 decimals).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "common/face/face_json.h"
#include "tests/fuzz/fuzz_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text = kinemo::fuzz::Text(data, size);
  auto track = kinemo::face::FaceTrackFromJson(text, "V.json");
  if (!track.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(track.status(), absl::StatusCode::kInvalidArgument);
    KINEMO_FUZZ_CHECK(track.status().message().substr(0, 6) == "V.json", "the error does not name the file");
    return 0;
  }
  KINEMO_FUZZ_CHECK(track->frame_time_s > 0 && track->frame_time_s <= 1, "frame_time_s out of range");
  for (const auto& f : track->frames) {
    KINEMO_FUZZ_CHECK(std::isfinite(f.time_s) && f.time_s >= 0, "time_s out of range");
    for (float w : f.ovr) KINEMO_FUZZ_CHECK(w >= 0 && w <= 1, "ovr weight out of range");
    for (float w : f.categories) KINEMO_FUZZ_CHECK(w >= 0 && w <= 1, "category weight out of range");
    KINEMO_FUZZ_CHECK(std::abs(f.jaw_open_deg) <= kinemo::face::kMaxJawDeg, "jaw out of range");
    KINEMO_FUZZ_CHECK(f.blink_left >= 0 && f.blink_left <= 1 && f.brow_raise >= 0 && f.brow_raise <= 1,
                      "blink or brow out of range");
  }
  auto again = kinemo::face::FaceTrackFromJson(kinemo::face::FaceTrackToJson(*track), "rewritten");
  KINEMO_FUZZ_CHECK(again.ok(), again.status().ToString());
  KINEMO_FUZZ_CHECK(again->frames.size() == track->frames.size(), "write → read changed the frame count");
  return 0;
}
