// Node transforms of a glTF document (internal to kinemo_retarget).
#pragma once

#include <tiny_gltf.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "common/status/status.h"

namespace kinemo::retarget {

// The nearest rotation to a matrix whose columns may be scaled (uniform or
// not): columns normalised, then the rotation of the quaternion it gives.
Eigen::Matrix3d Orthonormalized(const Eigen::Matrix3d& m);

struct NodeTree {
  std::vector<int> parent;              // -1 for scene roots
  std::vector<int> depth;
  std::vector<Eigen::Matrix4d> global;  // default-pose world matrix
};

// Parents, depths and default-pose world matrices; INVALID_ARGUMENT for a
// node with two parents, a cycle or a child index out of range.
StatusOr<NodeTree> BuildNodeTree(const tinygltf::Model& model);

// A node's local matrix (its `matrix`, or T·R·S).
Eigen::Matrix4d NodeLocalMatrix(const tinygltf::Node& node);

// The skin's inverse bind matrices (empty when the skin has none: identity
// by the specification, the caller then uses the default pose).
StatusOr<std::vector<Eigen::Matrix4d>> ReadInverseBindMatrices(const tinygltf::Model& model, const tinygltf::Skin& skin);

}  // namespace kinemo::retarget
