// kinemo animate WAV --rig RIG.glb -o OUT.glb: the animate result (BVH on
// the library's skeleton) retargeted onto the user's character.

#include <cstdio>
#include <filesystem>
#include <unistd.h>

#include "absl/strings/str_replace.h"
#include "services/cli/retarget_files.h"

namespace kinemo::cli {

StatusOr<AnimateRig> PrepareAnimateRig(const std::string& rig, const std::string& map, std::string* bvh_output,
                                       const std::string& face_map) {
  AnimateRig job{rig, map, *bvh_output, "", face_map, std::nullopt};
  RetargetFiles check{.input = "x.bvh", .rig = rig, .output = job.final_output, .map = map, .face_map = face_map,
                      .rig_field = "--rig"};
  KINEMO_RETURN_IF_ERROR(ValidateRetargetFiles(check));
  auto loaded = LoadTargetRig(check);
  if (!loaded.ok()) return loaded.status();
  if (auto face = LoadFaceMap(check, *loaded); !face.ok()) return face.status();
  job.temporary_bvh = (std::filesystem::temp_directory_path() /
                       kinemo::StrCat("kinemo-animate-", getpid(), ".bvh")).string();
  *bvh_output = job.temporary_bvh;
  return job;
}

Status RetargetAnimateResult(const AnimateRig& job, bool json) {
  RetargetFiles f{.input = job.temporary_bvh,
                  .rig = job.rig,
                  .output = job.final_output,
                  .map = job.map,
                  .face_map = job.face_map,
                  .face = job.face ? &*job.face : nullptr,
                  .face_field = "the animate result's face",
                  .rig_field = "--rig"};
  f.input_option = "the animated motion";
  auto report = RetargetFile(f);
  std::error_code ec;
  std::filesystem::remove(job.temporary_bvh, ec);
  if (!report.ok()) {
    // The temporary BVH is gone: the message names the motion, not its path.
    return Status(report.status().code(),
                  absl::StrReplaceAll(report.status().message(), {{job.temporary_bvh + ": ", ""},
                                                                  {job.temporary_bvh, "the animated motion"}}));
  }
  if (json) {
    std::printf("%s\n", report->dump().c_str());
  } else {
    std::printf("retargeted onto %s (%s): %zu roles mapped, root scale %.3f -> %s\n", job.rig.c_str(),
                (*report)["target_family"].get<std::string>().c_str(), (*report)["mapped_roles"].size(),
                (*report)["root_scale"].get<double>(), job.final_output.c_str());
  }
  return absl::OkStatus();
}

}  // namespace kinemo::cli
