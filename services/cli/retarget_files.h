// File-level retargeting shared by `kinemo retarget` and `kinemo animate
// --rig` (implemented in cmd_retarget.cc).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::cli {

struct RetargetFiles {
  std::string input;       // BVH
  std::string rig;         // .glb / .gltf / .vrm, or a .bvh skeleton
  std::string output;      // .glb (glTF rigs) or .bvh
  std::string map;         // JSON role map of the target rig (optional)
  std::string source_map;  // JSON role map of the input (optional)
  double source_meters_per_unit = 0;  // 0: estimated from the legs
  bool fingers = true;
  // How errors name the rig, the output and the input (`kinemo animate
  // --rig` names its own options).
  std::string rig_option = "--to", output_option = "-o", input_option = "input";
};

// Checks the options (file kinds) before any work: INVALID_ARGUMENT naming the option.
Status ValidateRetargetFiles(const RetargetFiles& f);

// The target rig of `f` (f.rig with f.map): errors name f.rig_option / --map.
StatusOr<retarget::Rig> LoadTargetRig(const RetargetFiles& f);

// Reads, retargets, writes; returns {mapped_roles, unmapped_roles, frames,
// root_scale, seconds, duration_s, source_family, target_family, output}.
StatusOr<nlohmann::json> RetargetFile(const RetargetFiles& f);

}  // namespace kinemo::cli

namespace kinemo::cli {

// `kinemo animate --rig RIG -o OUT`: before the stack runs, checks the rig
// (loads it: errors name --rig) and the output, and points *bvh_output at a
// temporary BVH for the animate result; afterwards RetargetAnimateResult
// puts that motion on the rig into `final_output` and removes the
// temporary file. Implemented in cmd_animate_rig.cc.
struct AnimateRig {
  std::string rig, map, final_output, temporary_bvh;
};
StatusOr<AnimateRig> PrepareAnimateRig(const std::string& rig, const std::string& map, std::string* bvh_output);
Status RetargetAnimateResult(const AnimateRig& job, bool json);

}  // namespace kinemo::cli
