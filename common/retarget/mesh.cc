#include "common/retarget/mesh.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>

#include "common/motion/kinematics.h"
#include "common/retarget/gltf.h"
#include "common/retarget/transform.h"

namespace kinemo::retarget {
namespace {

int Components(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    default: return 0;
  }
}

}  // namespace

StatusOr<std::vector<float>> ReadAccessor(const tinygltf::Model& model, int index, int components,
                                          const std::string& field) {
  if (index < 0 || index >= static_cast<int>(model.accessors.size())) return InvalidField(field, "accessor out of range");
  const tinygltf::Accessor& acc = model.accessors[static_cast<size_t>(index)];
  if (Components(acc.type) != components) return InvalidField(field, "must have ", components, " components");
  int size = 0;
  switch (acc.componentType) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: size = 4; break;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: size = 2; break;
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: size = 1; break;
    default: return InvalidField(field, "component type ", acc.componentType, " is not supported");
  }
  if (acc.count > (size_t{1} << 28)) return InvalidField(field, "count ", acc.count, " is too large");
  std::vector<float> out(acc.count * static_cast<size_t>(components), 0.0f);
  if (acc.bufferView < 0) return out;  // all zeros (sparse accessors are not read)
  if (acc.bufferView >= static_cast<int>(model.bufferViews.size())) return InvalidField(field, "bufferView out of range");
  const tinygltf::BufferView& view = model.bufferViews[static_cast<size_t>(acc.bufferView)];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) return InvalidField(field, "buffer out of range");
  const std::vector<unsigned char>& data = model.buffers[static_cast<size_t>(view.buffer)].data;
  const size_t element = static_cast<size_t>(size * components);
  const size_t stride = view.byteStride ? view.byteStride : element;
  if (acc.count == 0) return out;
  if (acc.byteOffset > view.byteLength || view.byteOffset > data.size() || stride > 256) {
    return InvalidField(field, "runs past its buffer");
  }
  const size_t start = view.byteOffset + acc.byteOffset;
  const size_t end = acc.byteOffset + stride * (acc.count - 1) + element;
  if (stride < element || end > view.byteLength || view.byteOffset + end > data.size()) {
    return InvalidField(field, "runs past its buffer");
  }
  for (size_t k = 0; k < acc.count; ++k) {
    const unsigned char* p = data.data() + start + k * stride;
    for (int c = 0; c < components; ++c) {
      float v = 0;
      const unsigned char* q = p + static_cast<size_t>(c * size);
      switch (acc.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: std::memcpy(&v, q, 4); break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
          std::uint32_t u;
          std::memcpy(&u, q, 4);
          v = static_cast<float>(u);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          std::uint16_t u;
          std::memcpy(&u, q, 2);
          v = acc.normalized ? static_cast<float>(u) / 65535.0f : static_cast<float>(u);
          break;
        }
        // KHR_mesh_quantization: signed normalized values are max(c / 2^(b-1)-1, -1).
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
          std::int16_t i;
          std::memcpy(&i, q, 2);
          v = acc.normalized ? std::max(static_cast<float>(i) / 32767.0f, -1.0f) : static_cast<float>(i);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
          const auto i = static_cast<std::int8_t>(*q);
          v = acc.normalized ? std::max(static_cast<float>(i) / 127.0f, -1.0f) : static_cast<float>(i);
          break;
        }
        default:
          v = acc.normalized ? static_cast<float>(*q) / 255.0f : static_cast<float>(*q);
          break;
      }
      if (!std::isfinite(v)) return InvalidField(field, "value ", k, " is not finite");
      out[k * static_cast<size_t>(components) + static_cast<size_t>(c)] = v;
    }
  }
  return out;
}

StatusOr<CharacterMesh> LoadCharacterMesh(const Rig& rig) {
  if (!rig.gltf) return absl::FailedPreconditionError(kinemo::StrCat(rig.name, ": not a glTF character (no mesh)"));
  const tinygltf::Model& model = rig.gltf->model;
  KINEMO_ASSIGN_OR_RETURN(NodeTree tree, BuildNodeTree(model));
  std::map<int, int> joint_of_node;
  for (size_t j = 0; j < rig.node.size(); ++j) joint_of_node[rig.node[j]] = static_cast<int>(j);
  CharacterMesh mesh;
  for (const tinygltf::Material& m : model.materials) {
    const auto& f = m.pbrMetallicRoughness.baseColorFactor;
    mesh.base_colors.emplace_back(f.size() == 4 ? Eigen::Vector4f(static_cast<float>(f[0]), static_cast<float>(f[1]),
                                                                  static_cast<float>(f[2]), static_cast<float>(f[3]))
                                                : Eigen::Vector4f(1, 1, 1, 1));
  }
  const int default_material = static_cast<int>(mesh.base_colors.size());
  mesh.base_colors.emplace_back(0.5f, 0.5f, 0.5f, 1.0f);
  for (size_t n = 0; n < model.nodes.size(); ++n) {
    const tinygltf::Node& node = model.nodes[n];
    if (node.mesh < 0 || node.skin < 0) continue;
    if (node.mesh >= static_cast<int>(model.meshes.size()) || node.skin >= static_cast<int>(model.skins.size())) {
      return InvalidField(kinemo::StrCat("nodes[", n, "]"), "mesh or skin out of range");
    }
    const tinygltf::Skin& skin = model.skins[static_cast<size_t>(node.skin)];
    std::vector<int> skin_joint(skin.joints.size(), -1);
    for (size_t k = 0; k < skin.joints.size(); ++k) {
      if (auto it = joint_of_node.find(skin.joints[k]); it != joint_of_node.end()) skin_joint[k] = it->second;
    }
    // The skin's bind space: the mesh node's world, or what the joints' bind
    // pose says when a tool folded a transform into the inverse bind
    // matrices (transform.h SkinBindSpace; gltfpack's quantization).
    for (int jn : skin.joints) {
      if (jn < 0 || jn >= static_cast<int>(model.nodes.size())) return InvalidField(kinemo::StrCat("skins[", node.skin, "].joints"), "node out of range");
    }
    KINEMO_ASSIGN_OR_RETURN(const std::vector<Eigen::Matrix4d> ibm, ReadInverseBindMatrices(model, skin));
    const Eigen::Matrix4d world =
        SkinBindSpace(model, tree, node.skin, skin.joints, ibm, -1, static_cast<int>(n));
    const Eigen::Matrix3d normal_matrix = world.block<3, 3>(0, 0).inverse().transpose();
    const tinygltf::Mesh& gm = model.meshes[static_cast<size_t>(node.mesh)];
    for (size_t p = 0; p < gm.primitives.size(); ++p) {
      const tinygltf::Primitive& prim = gm.primitives[p];
      const std::string field = kinemo::StrCat("meshes[", node.mesh, "].primitives[", p, "]");
      if (prim.mode != -1 && prim.mode != TINYGLTF_MODE_TRIANGLES) continue;
      auto attr = [&](const char* name) { auto it = prim.attributes.find(name); return it == prim.attributes.end() ? -1 : it->second; };
      if (attr("POSITION") < 0 || attr("JOINTS_0") < 0 || attr("WEIGHTS_0") < 0) continue;
      KINEMO_ASSIGN_OR_RETURN(std::vector<float> pos, ReadAccessor(model, attr("POSITION"), 3, field + ".POSITION"));
      KINEMO_ASSIGN_OR_RETURN(std::vector<float> jnt, ReadAccessor(model, attr("JOINTS_0"), 4, field + ".JOINTS_0"));
      KINEMO_ASSIGN_OR_RETURN(std::vector<float> wgt, ReadAccessor(model, attr("WEIGHTS_0"), 4, field + ".WEIGHTS_0"));
      std::vector<float> nrm;
      if (attr("NORMAL") >= 0) {
        KINEMO_ASSIGN_OR_RETURN(nrm, ReadAccessor(model, attr("NORMAL"), 3, field + ".NORMAL"));
      }
      const size_t count = pos.size() / 3;
      if (jnt.size() / 4 != count || wgt.size() / 4 != count || (!nrm.empty() && nrm.size() / 3 != count)) {
        return InvalidField(field, "attributes have different counts");
      }
      const int base = static_cast<int>(mesh.positions.size());
      for (size_t v = 0; v < count; ++v) {
        const Eigen::Vector3d x = (world * Eigen::Vector4d(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2], 1)).head<3>();
        mesh.positions.push_back(x.cast<float>());
        Eigen::Vector3d nv = nrm.empty() ? Eigen::Vector3d::UnitY()
                                         : Eigen::Vector3d(normal_matrix * Eigen::Vector3d(nrm[3 * v], nrm[3 * v + 1], nrm[3 * v + 2]));
        if (nv.norm() > 0) nv.normalize();
        mesh.normals.push_back(nv.cast<float>());
        std::array<int, 4> js{};
        Eigen::Vector4f ws;
        float sum = 0;
        for (int c = 0; c < 4; ++c) {
          const float w = wgt[4 * v + static_cast<size_t>(c)];
          const float jf = jnt[4 * v + static_cast<size_t>(c)];
          int j = 0;
          if (w > 0) {
            if (jf < 0 || jf >= static_cast<float>(skin_joint.size())) {
              return InvalidField(field + ".JOINTS_0", "joint ", jf, " of vertex ", v, " is outside skin ", node.skin);
            }
            j = skin_joint[static_cast<size_t>(jf)];
          }
          if (j < 0) j = 0;  // a skin joint that is not the rig's: the root holds it
          js[static_cast<size_t>(c)] = j;
          ws[c] = w > 0 ? w : 0;
          sum += ws[c];
        }
        if (sum > 0) {
          ws /= sum;
        } else {
          ws = Eigen::Vector4f(1, 0, 0, 0);
        }
        mesh.joints.push_back(js);
        mesh.weights.push_back(ws);
      }
      const int material = prim.material >= 0 && prim.material < default_material ? prim.material : default_material;
      std::vector<float> idx;
      if (prim.indices >= 0) {
        KINEMO_ASSIGN_OR_RETURN(idx, ReadAccessor(model, prim.indices, 1, field + ".indices"));
      } else {
        for (size_t v = 0; v < count; ++v) idx.push_back(static_cast<float>(v));
      }
      for (size_t t = 0; t + 2 < idx.size(); t += 3) {
        std::array<int, 3> tri{};
        for (int c = 0; c < 3; ++c) {
          const float i = idx[t + static_cast<size_t>(c)];
          if (i < 0 || i >= static_cast<float>(count)) return InvalidField(field + ".indices", "index ", i, " out of range");
          tri[static_cast<size_t>(c)] = base + static_cast<int>(i);
        }
        mesh.triangles.push_back(tri);
        mesh.triangle_material.push_back(material);
      }
    }
  }
  if (mesh.triangles.empty()) {
    return absl::FailedPreconditionError(kinemo::StrCat(rig.name, ": no skinned triangles to draw"));
  }
  mesh.min_corner = mesh.max_corner = mesh.positions.front();
  for (const auto& p : mesh.positions) {
    mesh.min_corner = mesh.min_corner.cwiseMin(p);
    mesh.max_corner = mesh.max_corner.cwiseMax(p);
  }
  return mesh;
}

Status ComputeSkinPose(const Rig& rig, std::span<const double> frame, SkinPose* out) {
  const int n = rig.skeleton.num_joints();
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(n));
  std::vector<Eigen::Matrix3d> rot(static_cast<size_t>(n));
  KINEMO_RETURN_IF_ERROR(motion::ComputeWorldPose(rig.skeleton, frame, pos, rot));
  const std::vector<Eigen::Vector3d> rest = rig.RestPositions();
  out->rotation.resize(static_cast<size_t>(n));
  out->translation.resize(static_cast<size_t>(n));
  for (size_t j = 0; j < static_cast<size_t>(n); ++j) {
    out->rotation[j] = rot[j].cast<float>();
    out->translation[j] = (pos[j] - rot[j] * rest[j]).cast<float>();
  }
  return absl::OkStatus();
}

void SkinMesh(const CharacterMesh& mesh, const SkinPose& pose, std::vector<Eigen::Vector3f>* positions,
              std::vector<Eigen::Vector3f>* normals) {
  const size_t n = mesh.positions.size();
  positions->resize(n);
  if (normals != nullptr) normals->resize(n);
  for (size_t v = 0; v < n; ++v) {
    Eigen::Matrix3f r = Eigen::Matrix3f::Zero();
    Eigen::Vector3f t = Eigen::Vector3f::Zero();
    for (int c = 0; c < 4; ++c) {
      const float w = mesh.weights[v][c];
      if (w == 0) continue;
      const size_t j = static_cast<size_t>(mesh.joints[v][static_cast<size_t>(c)]);
      r += w * pose.rotation[j];
      t += w * pose.translation[j];
    }
    (*positions)[v] = r * mesh.positions[v] + t;
    if (normals != nullptr) (*normals)[v] = (r * mesh.normals[v]).normalized();
  }
}

}  // namespace kinemo::retarget
