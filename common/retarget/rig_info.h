// What a rig is and offers, as JSON: `kinemo rig info RIG --json`, the
// planner's rig summaries (kinemo rig ls --json), the studio.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "common/retarget/face_map.h"
#include "common/retarget/rig.h"

namespace kinemo::retarget {

// "vrm1" (VRMC_vrm), "vrm0" (VRM), "glb", "gltf" (a .gltf text file), "bvh".
std::string RigFormat(const Rig& rig);

// {name, format, compression, family, joints, mapped_roles, unmapped_roles,
//  leg_length_m, hips_height_m, morph_targets: [{mesh, targets}],
//  face_channels: [{kind, name, mesh, target, family, group, driven,
//  driven_by, vmc_name}], face_channels_driven, mouth_family,
//  jaw_bone: {name, found_by, hinge_axis, max_deg} | null,
//  jaw_full_open_deg (the jaw input's scale), vowel_open_deg (the jaw
//  opening at which a vowel shows at its full weight; 0 = the weights alone),
//  vrm: {spec_version, expressions, look_at} (VRM only)}.
nlohmann::json RigInfoJson(const Rig& rig, const FaceMap& face);

// The few facts a stored rig's summary carries (kinemo rig push / ls):
// {format, family, joints, mapped_roles, unmapped_roles, leg_length_m,
//  face_channels_driven, mouth_family, jaw_bone}.
nlohmann::json RigSummaryJson(const Rig& rig, const FaceMap& face);

}  // namespace kinemo::retarget
