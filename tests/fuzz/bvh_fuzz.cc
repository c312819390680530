// Fuzzes the BVH reader (common/motion/bvh_reader.cc) and what every reader
// of a parsed clip does next: forward kinematics, body-region mapping,
// resampling, and a write → read round trip that must give the same clip.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string_view>
#include <vector>

#include "common/motion/body_regions.h"
#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/motion/resample.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

using kinemo::motion::Clip;

bool SameClip(const Clip& a, const Clip& b) {
  if (a.skeleton.num_joints() != b.skeleton.num_joints() || a.frame_time_s != b.frame_time_s ||
      a.frames.rows() != b.frames.rows() || a.frames.cols() != b.frames.cols()) {
    return false;
  }
  for (int j = 0; j < a.skeleton.num_joints(); ++j) {
    const auto& ja = a.skeleton.joint(j);
    const auto& jb = b.skeleton.joint(j);
    if (ja.name != jb.name || ja.parent != jb.parent || ja.channels != jb.channels ||
        ja.offset != jb.offset || ja.end_site != jb.end_site ||
        ja.position_relative_to_offset != jb.position_relative_to_offset) {
      return false;
    }
  }
  return a.frames.size() == 0 ||
         std::memcmp(a.frames.data(), b.frames.data(),
                     sizeof(double) * static_cast<size_t>(a.frames.size())) == 0;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text = kinemo::fuzz::Text(data, size);
  auto clip = kinemo::motion::ParseBvh(text, "fuzz.bvh");
  if (!clip.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(clip.status(), absl::StatusCode::kInvalidArgument);
    return 0;
  }
  KINEMO_FUZZ_CHECK(clip->Validate().ok(), clip->Validate().ToString());

  // Forward kinematics of the first frames (what the planner and the preview do).
  const int joints = clip->skeleton.num_joints();
  std::vector<Eigen::Vector3d> positions(static_cast<size_t>(joints));
  std::vector<Eigen::Matrix3d> rotations(static_cast<size_t>(joints));
  for (int f = 0; f < std::min(clip->num_frames(), 4); ++f) {
    const auto s =
        kinemo::motion::ComputeWorldPose(clip->skeleton, clip->frame(f), positions, rotations);
    KINEMO_FUZZ_CHECK(s.ok(), s.ToString());
  }
  const auto regions = kinemo::motion::MapBodyRegions(clip->skeleton);
  (void)kinemo::motion::FindKeyJoints(clip->skeleton, regions);

  // The planner resamples every library clip to the library's rate.
  auto resampled = kinemo::motion::Resample(*clip, 30.0);
  if (!resampled.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(resampled.status(), absl::StatusCode::kInvalidArgument);
  }

  // Write → read gives the same clip (numbers are written to round-trip).
  auto written = kinemo::motion::WriteBvh(*clip);
  KINEMO_FUZZ_CHECK(written.ok(), written.status().ToString());
  auto reread = kinemo::motion::ParseBvh(*written, "rewritten.bvh");
  KINEMO_FUZZ_CHECK(reread.ok(), reread.status().ToString());
  KINEMO_FUZZ_CHECK(SameClip(*clip, *reread), "write → read changed the clip");
  return 0;
}
