// A glTF character's skinned meshes on its rig's joints, and linear-blend
// skinning of them under a frame of motion on the rig's skeleton (e.g. a
// Retargeter's output). Plain C++ (Eigen, tinygltf); the AR view of the cube
// (services/cube_tracker/ar) draws these.
//
// Every mesh node with a skin contributes its triangles (mode TRIANGLES,
// indexed or not); vertices are put in the rig's world (the bind pose, y up,
// metres for glTF: the mesh node's world matrix applied, as the rig's rest
// positions are), their JOINTS_0 mapped onto the rig's joints through the
// nodes (a skin whose joints are nodes of the rig), WEIGHTS_0 normalised.
// Colour is the material's baseColorFactor (textures are not sampled).
//
// Skinning: joint j posed at world position p_j with world rotation R_j
// (rotation relative to its rest, the rig's convention) moves a bind-pose
// point x to R_j (x − r_j) + p_j, r_j its rest position; a vertex takes the
// weighted sum over its four joints.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::retarget {

struct CharacterMesh {
  std::vector<Eigen::Vector3f> positions;  // bind pose, the rig's world
  std::vector<Eigen::Vector3f> normals;    // unit, bind pose
  std::vector<std::array<int, 4>> joints;  // rig joint indices
  std::vector<Eigen::Vector4f> weights;    // sum 1
  std::vector<std::array<int, 3>> triangles;  // counter-clockwise seen from outside
  std::vector<int> triangle_material;         // index into base_colors
  std::vector<Eigen::Vector4f> base_colors;   // linear RGBA per material (+1: the default grey)
  Eigen::Vector3f min_corner = Eigen::Vector3f::Zero(), max_corner = Eigen::Vector3f::Zero();  // bind pose bounds
};

// INVALID_ARGUMENT naming the glTF part that is wrong (an accessor of the
// wrong type, a joint index outside its skin, ...); FAILED_PRECONDITION when
// `rig` has no glTF document or no skinned triangles.
StatusOr<CharacterMesh> LoadCharacterMesh(const Rig& rig);

// Per rig joint, the transform a frame applies to bind-pose points:
// x -> rotation · x + translation.
struct SkinPose {
  std::vector<Eigen::Matrix3f> rotation;
  std::vector<Eigen::Vector3f> translation;
};
// `frame` holds rig.skeleton's channel values. Fails only on size mismatch.
Status ComputeSkinPose(const Rig& rig, std::span<const double> frame, SkinPose* out);

// The posed vertices (and normals, when `normals` is not null), resized to
// the mesh's vertex count.
void SkinMesh(const CharacterMesh& mesh, const SkinPose& pose, std::vector<Eigen::Vector3f>* positions,
              std::vector<Eigen::Vector3f>* normals);

}  // namespace kinemo::retarget
