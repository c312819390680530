// Node transforms of a glTF document (internal to kinemo_retarget).
#pragma once

#include <tiny_gltf.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
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

// An accessor's values as floats (count × components), normalised integers
// scaled to [0, 1] (signed: [-1, 1]) when `normalized` (KHR_mesh_quantization);
// `components` is the number expected. INVALID_ARGUMENT naming `field` for an
// accessor of another shape, out of range or running past its buffer.
StatusOr<std::vector<float>> ReadAccessor(const tinygltf::Model& model, int index, int components,
                                          const std::string& field);

// The skin's inverse bind matrices (empty when the skin has none: identity
// by the specification, the caller then uses the default pose).
StatusOr<std::vector<Eigen::Matrix4d>> ReadInverseBindMatrices(const tinygltf::Model& model, const tinygltf::Skin& skin);

// The space a skin's vertices (and so its inverse bind matrices) are in,
// world from mesh: when most joints' default pose is their bind pose, the
// one matrix joint world × inverse bind matrix they agree on (tools fold
// transforms into the inverse bind matrices: gltfpack's and glTF-Transform's
// quantization put the positions' dequantization there); else the world
// matrix of a mesh node using the skin (three.js' bindMatrix; Blender
// exports give it the armature's transform; `mesh_node` >= 0: that node's);
// else the parent of the topmost joint (`top_joint_node`, -1 = none).
// `skin_index` -1: no skin. `ibm` has one matrix per skin joint, or none.
Eigen::Matrix4d SkinBindSpace(const tinygltf::Model& model, const NodeTree& tree, int skin_index,
                              const std::vector<int>& skin_joints, const std::vector<Eigen::Matrix4d>& ibm,
                              int top_joint_node, int mesh_node = -1);

// Members and elements of extension / extras JSON (tinygltf::Value), safe on
// values of any type: a missing member or a value of another type gives a
// null Value (tinygltf's own Get asserts the type).
inline const tinygltf::Value& Member(const tinygltf::Value& v, const std::string& key) {
  static const tinygltf::Value kNull;
  return v.IsObject() ? v.Get(key) : kNull;
}
inline const tinygltf::Value& Element(const tinygltf::Value& v, size_t i) {
  static const tinygltf::Value kNull;
  return v.IsArray() && i < v.ArrayLen() ? v.Get(static_cast<int>(i)) : kNull;
}

}  // namespace kinemo::retarget
