// Paired takes for the face model (docs/face.md): <name>.wav + <name>.bvh
// (an SMPL-X skeleton whose `jaw` joint is the captured face) +
// <name>.TextGrid (a `phones` interval tier), the layout of
// tests/data/paired/beat2.
#pragma once

#include <string>
#include <vector>

#include "common/status/status.h"
#include "services/prosody/core/face_model.h"

namespace kinemo::prosody {

// The captured jaw opening of a BVH's `jaw` joint (common/face/jaw.h), per
// frame; *frame_time_s is the BVH's. INVALID_ARGUMENT naming the file when
// it has no jaw with Z, X and Y rotations.
StatusOr<std::vector<double>> ReadJawOpenings(const std::string& bvh_path, double* frame_time_s);

// One take of `dir` (audio resampled to 16 kHz). Errors name the file.
StatusOr<FaceTrainingTake> ReadFaceTake(const std::string& dir, const std::string& name);

// The names of the takes of `dir` that have all three files, sorted.
std::vector<std::string> FaceTakeNames(const std::string& dir);

}  // namespace kinemo::prosody
