// File-level retargeting shared by `kinemo retarget` and `kinemo animate
// --rig` (implemented in cmd_retarget.cc).
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "common/face/face_frame.h"
#include "common/retarget/face_map.h"
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
  std::string face_map;    // JSON face map of the target rig (optional; --face-map)
  std::string visemes;     // --visemes V.json (read by ReadFaceFile into `face`)
  // The face to put on the rig (morph weights and jaw; null: none). Its
  // frames are on the input's clock (frame i at i × frame_time_s).
  const face::FaceTrack* face = nullptr;
  std::string face_field = "--visemes";  // names the face's source in errors
  std::string rig_field = "--to";        // names the rig option in errors
  // How errors name the output and the input (`kinemo animate --rig` names
  // its own).
  std::string output_option = "-o", input_option = "input";
};

// Checks the options (file kinds) before any work: INVALID_ARGUMENT naming the option.
Status ValidateRetargetFiles(const RetargetFiles& f);

// The target rig of `f` (f.rig with f.map): errors name f.rig_field / --map.
StatusOr<retarget::Rig> LoadTargetRig(const RetargetFiles& f);

// A viseme file (common/face/face_json.h) as a face track: errors name `field`.
StatusOr<face::FaceTrack> ReadFaceFile(const std::string& path, std::string_view field);

// The target rig's face map (f.face_map read as the map file): errors name --face-map.
StatusOr<retarget::FaceMap> LoadFaceMap(const RetargetFiles& f, const retarget::Rig& rig);

// Reads, retargets, writes; returns {mapped_roles, unmapped_roles, frames,
// root_scale, seconds, duration_s, source_family, target_family, output,
// face_channels_mapped, face_frames, jaw_bone, ...}.
StatusOr<nlohmann::json> RetargetFile(const RetargetFiles& f);

}  // namespace kinemo::cli

namespace kinemo::cli {

// `kinemo animate --rig RIG -o OUT`: before the stack runs, checks the rig
// (loads it: errors name --rig) and the output, and points *bvh_output at a
// temporary BVH for the animate result; afterwards RetargetAnimateResult
// puts that motion on the rig into `final_output` and removes the
// temporary file. Implemented in cmd_animate_rig.cc.
struct AnimateRig {
  std::string rig, map, final_output, temporary_bvh, face_map;
  // The animate result's face (the coordinator's face track), when it has one.
  std::optional<face::FaceTrack> face;
};
StatusOr<AnimateRig> PrepareAnimateRig(const std::string& rig, const std::string& map, std::string* bvh_output,
                                       const std::string& face_map = "");
Status RetargetAnimateResult(const AnimateRig& job, bool json);

}  // namespace kinemo::cli
