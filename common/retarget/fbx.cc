// FBX through assimp (fbx.h): the reader (assimp's scene -> a glTF document
// in memory) and the writer of an animated FBX rig. The byte-level checks
// and repairs around assimp are in fbx_bytes.cc.
#include "common/retarget/fbx.h"

#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <assimp/Exporter.hpp>
#include <assimp/Importer.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include "common/retarget/fbx_bytes.h"
#include "common/retarget/transform.h"

namespace kinemo::retarget {
namespace {

Eigen::Matrix4d ToEigen(const aiMatrix4x4& m) {
  Eigen::Matrix4d e;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) e(r, c) = m[r][c];
  }
  return e;
}

// A matrix whose translation is in file units, in metres.
Eigen::Matrix4d ScaleTranslation(Eigen::Matrix4d m, double s) {
  m.block<3, 1>(0, 3) *= s;
  return m;
}

bool FiniteMatrix(const Eigen::Matrix4d& m) { return m.allFinite() && std::abs(m.block<3, 3>(0, 0).determinant()) > 1e-30; }

// glTF node TRS of a local matrix (shear, which glTF cannot hold, is dropped).
void SetNodeTransform(tinygltf::Node& node, const Eigen::Matrix4d& m) {
  Eigen::Matrix3d l = m.block<3, 3>(0, 0);
  Eigen::Vector3d s(l.col(0).norm(), l.col(1).norm(), l.col(2).norm());
  if (l.determinant() < 0) s.x() = -s.x();
  Eigen::Matrix3d r = l;
  for (int c = 0; c < 3; ++c) r.col(c) /= s[c];
  const Eigen::Quaterniond q = Eigen::Quaterniond(Orthonormalized(r)).normalized();
  const Eigen::Vector3d t = m.block<3, 1>(0, 3);
  if (t.squaredNorm() > 0) node.translation = {t.x(), t.y(), t.z()};
  if (std::abs(q.w()) < 1 - 1e-12) node.rotation = {q.x(), q.y(), q.z(), q.w()};
  if ((s - Eigen::Vector3d::Ones()).cwiseAbs().maxCoeff() > 1e-9) node.scale = {s.x(), s.y(), s.z()};
}

// Appends bytes to buffer 0 (4-byte aligned) as a view; returns its index.
int AppendView(tinygltf::Model& model, const void* bytes, size_t size, int target) {
  std::vector<unsigned char>& data = model.buffers[0].data;
  while (data.size() % 4 != 0) data.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = data.size();
  view.byteLength = size;
  view.target = target;
  const auto* p = static_cast<const unsigned char*>(bytes);
  data.insert(data.end(), p, p + size);
  model.bufferViews.push_back(view);
  return static_cast<int>(model.bufferViews.size()) - 1;
}

template <typename T>
int AppendAccessor(tinygltf::Model& model, const std::vector<T>& values, int component, int type, size_t count,
                   int target, bool bounds = false, int components = 3) {
  tinygltf::Accessor acc;
  acc.bufferView = AppendView(model, values.data(), values.size() * sizeof(T), target);
  acc.componentType = component;
  acc.type = type;
  acc.count = count;
  if (bounds && count > 0) {
    acc.minValues.assign(static_cast<size_t>(components), 1e300);
    acc.maxValues.assign(static_cast<size_t>(components), -1e300);
    for (size_t i = 0; i < count; ++i) {
      for (int c = 0; c < components; ++c) {
        const double v = values[i * static_cast<size_t>(components) + static_cast<size_t>(c)];
        acc.minValues[c] = std::min(acc.minValues[c], v);
        acc.maxValues[c] = std::max(acc.maxValues[c], v);
      }
    }
  }
  model.accessors.push_back(acc);
  return static_cast<int>(model.accessors.size()) - 1;
}

bool EndsWithEnd(std::string_view name) {
  if (name.size() < 3) return false;
  std::string tail(name.substr(name.size() - 3));
  for (char& c : tail) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return tail == "end";
}

// The file's axes as a rotation into glTF's (x right, y up, z front), from
// the GlobalSettings assimp keeps as metadata. Identity when absent.
StatusOr<Eigen::Matrix3d> AxisConversion(const aiScene& scene, const std::string& name) {
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
  const aiMetadata* meta = scene.mMetaData;
  if (meta == nullptr) return a;
  int32_t up = 1, up_sign = 1, front = 2, front_sign = 1, coord = 0, coord_sign = 1;
  meta->Get("UpAxis", up);
  meta->Get("UpAxisSign", up_sign);
  meta->Get("FrontAxis", front);
  meta->Get("FrontAxisSign", front_sign);
  meta->Get("CoordAxis", coord);
  meta->Get("CoordAxisSign", coord_sign);
  auto axis_ok = [](int32_t axis, int32_t sign) { return axis >= 0 && axis <= 2 && (sign == 1 || sign == -1); };
  if (!axis_ok(up, up_sign) || !axis_ok(front, front_sign) || !axis_ok(coord, coord_sign) || up == front ||
      up == coord || front == coord) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": GlobalSettings: the axes (UpAxis ", up, ", FrontAxis ",
                                                     front, ", CoordAxis ", coord, ") are not three distinct axes"));
  }
  // Row k of `a` picks the file's axis that becomes glTF's axis k.
  a.setZero();
  a(0, coord) = coord_sign;
  a(1, up) = up_sign;
  a(2, front) = front_sign;
  if (a.determinant() < 0) {
    // A left-handed system: the front axis turns round (FBX's "parity"
    // convention leaves front's sign to the tools; a mirror cannot be
    // written as a node rotation).
    a.row(2) = -a.row(2);
  }
  return a;
}

struct Builder {
  const aiScene& scene;
  const std::string& name;
  const FbxLimits& limits;
  double s = 0.01;            // metres per file unit
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
  tinygltf::Model model;
  std::vector<const aiNode*> nodes;          // glTF node index -> aiNode
  std::map<const aiNode*, int> node_index;
  std::vector<Eigen::Matrix4d> raw_global;   // per node, in the file's space and units
  std::map<std::string, int> node_of_name;   // first node of each name

  Status Fail(std::string_view part, std::string_view what) const {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": ", part, ": ", what));
  }

  // A point of the file (units, file axes) in glTF's space (metres, y up).
  Eigen::Matrix4d Baked(const Eigen::Matrix4d& raw) const {
    Eigen::Matrix4d a = Eigen::Matrix4d::Identity();
    a.block<3, 3>(0, 0) = axes;
    return a * ScaleTranslation(raw, s);
  }

  Status AddNodes() {
    std::vector<std::pair<const aiNode*, int>> stack = {{scene.mRootNode, -1}};
    while (!stack.empty()) {
      const auto [n, parent] = stack.back();
      stack.pop_back();
      if (nodes.size() >= limits.max_nodes) return Fail("nodes", kinemo::StrCat("more than ", limits.max_nodes));
      const int index = static_cast<int>(nodes.size());
      nodes.push_back(n);
      node_index[n] = index;
      node_of_name.emplace(n->mName.C_Str(), index);
      const Eigen::Matrix4d local = ToEigen(n->mTransformation);
      if (!FiniteMatrix(local)) return Fail(kinemo::StrCat("node ", n->mName.C_Str()), "transform is not finite or singular");
      raw_global.push_back(parent < 0 ? local : Eigen::Matrix4d(raw_global[static_cast<size_t>(parent)] * local));
      tinygltf::Node node;
      node.name = n->mName.C_Str();
      Eigen::Matrix4d baked_local = ScaleTranslation(local, s);
      if (parent < 0) {
        Eigen::Matrix4d a = Eigen::Matrix4d::Identity();
        a.block<3, 3>(0, 0) = axes;
        baked_local = a * baked_local;
      }
      SetNodeTransform(node, baked_local);
      model.nodes.push_back(node);
      if (parent >= 0) model.nodes[static_cast<size_t>(parent)].children.push_back(index);
      if (n->mNumChildren > limits.max_nodes) return Fail("nodes", kinemo::StrCat("more than ", limits.max_nodes));
      for (unsigned c = n->mNumChildren; c-- > 0;) {
        if (n->mChildren[c] == nullptr) return Fail(kinemo::StrCat("node ", n->mName.C_Str()), "null child");
        stack.push_back({n->mChildren[c], index});
      }
    }
    // Children in the file's order (the stack reversed them once, pushing
    // in reverse; indices are increasing already).
    for (tinygltf::Node& node : model.nodes) std::sort(node.children.begin(), node.children.end());
    return absl::OkStatus();
  }

  Status Build(std::shared_ptr<GltfSource>* out) {
    model.asset.version = "2.0";
    model.asset.generator = "kinemo (FBX through assimp)";
    model.buffers.emplace_back();
    KINEMO_RETURN_IF_ERROR(AddNodes());
    const int num_nodes = static_cast<int>(nodes.size());

    // Which node draws each mesh (the first that lists it).
    if (scene.mNumMeshes > limits.max_meshes) return Fail("meshes", kinemo::StrCat("more than ", limits.max_meshes));
    std::vector<int> mesh_node(scene.mNumMeshes, -1);
    for (int i = 0; i < num_nodes; ++i) {
      const aiNode* n = nodes[static_cast<size_t>(i)];
      for (unsigned k = 0; k < n->mNumMeshes; ++k) {
        const unsigned m = n->mMeshes[k];
        if (m >= scene.mNumMeshes) return Fail(kinemo::StrCat("node ", n->mName.C_Str()), "mesh index out of range");
        if (mesh_node[m] < 0) mesh_node[m] = i;
      }
    }
    std::vector<bool> is_mesh_node(static_cast<size_t>(num_nodes), false);
    for (int n : mesh_node) {
      if (n >= 0) is_mesh_node[static_cast<size_t>(n)] = true;
    }

    // The bones: nodes named by a mesh's bones, with their bind pose from
    // the cluster (offset = bind⁻¹ · mesh world, as assimp computes it).
    std::map<int, Eigen::Matrix4d> bind_raw;  // node -> bind world (file space)
    uint64_t vertices = 0;
    for (unsigned m = 0; m < scene.mNumMeshes; ++m) {
      const aiMesh* mesh = scene.mMeshes[m];
      if (mesh == nullptr) return Fail(kinemo::StrCat("meshes[", m, "]"), "missing");
      vertices += uint64_t{mesh->mNumVertices} * (1 + mesh->mNumAnimMeshes);
      if (vertices > limits.max_vertices) return Fail("meshes", kinemo::StrCat("more than ", limits.max_vertices, " vertices"));
      if (mesh_node[m] < 0) continue;
      for (unsigned b = 0; b < mesh->mNumBones; ++b) {
        const aiBone* bone = mesh->mBones[b];
        if (bone == nullptr) return Fail(kinemo::StrCat("mesh ", mesh->mName.C_Str()), "missing bone");
        auto it = node_of_name.find(bone->mName.C_Str());
        if (it == node_of_name.end()) {
          return Fail(kinemo::StrCat("mesh ", mesh->mName.C_Str(), " bone ", bone->mName.C_Str()), "has no node");
        }
        if (bind_raw.count(it->second)) continue;
        const Eigen::Matrix4d offset = ToEigen(bone->mOffsetMatrix);
        if (!FiniteMatrix(offset)) {
          return Fail(kinemo::StrCat("bone ", bone->mName.C_Str()), "offset matrix is not finite or singular");
        }
        const Eigen::Matrix4d bind = raw_global[static_cast<size_t>(mesh_node[m])] * offset.inverse();
        if (!FiniteMatrix(bind)) return Fail(kinemo::StrCat("bone ", bone->mName.C_Str()), "bind pose is not finite");
        bind_raw[it->second] = bind;
      }
    }

    // The skin's joints: the bones and the nodes between them; without
    // bones (a skeleton alone), every node but the root, the mesh nodes and
    // the "...end" leaves.
    std::vector<int> parent(static_cast<size_t>(num_nodes), -1);
    for (int i = 0; i < num_nodes; ++i) {
      for (int c : model.nodes[static_cast<size_t>(i)].children) parent[static_cast<size_t>(c)] = i;
    }
    std::set<int> joints;
    if (!bind_raw.empty()) {
      for (const auto& [node, bind] : bind_raw) {
        joints.insert(node);
        std::vector<int> path;
        for (int a = parent[static_cast<size_t>(node)]; a >= 0; a = parent[static_cast<size_t>(a)]) {
          if (bind_raw.count(a)) {
            joints.insert(path.begin(), path.end());
            break;
          }
          path.push_back(a);
        }
      }
    } else {
      for (int i = 1; i < num_nodes; ++i) {
        if (is_mesh_node[static_cast<size_t>(i)]) continue;
        const aiNode* n = nodes[static_cast<size_t>(i)];
        if (n->mNumChildren == 0 && EndsWithEnd(n->mName.C_Str())) continue;
        joints.insert(i);
      }
    }
    if (joints.empty()) return Fail("skeleton", "no bones (not a rigged character)");
    if (joints.size() > limits.max_bones) return Fail("skeleton", kinemo::StrCat("more than ", limits.max_bones, " bones"));

    tinygltf::Skin skin;
    skin.name = "skeleton";
    std::map<int, int> joint_of_node;
    std::vector<float> ibm;
    for (int node : joints) {  // increasing node index: parents first
      joint_of_node[node] = static_cast<int>(skin.joints.size());
      skin.joints.push_back(node);
      Eigen::Matrix4d bind;
      if (auto it = bind_raw.find(node); it != bind_raw.end()) {
        bind = Baked(it->second);
      } else {
        // A node between bones: its default pose under its parent's bind.
        const int p = parent[static_cast<size_t>(node)];
        auto pb = bind_raw.find(p);
        bind = pb != bind_raw.end()
                   ? Baked(Eigen::Matrix4d(pb->second * raw_global[static_cast<size_t>(p)].inverse() *
                                           raw_global[static_cast<size_t>(node)]))
                   : Baked(raw_global[static_cast<size_t>(node)]);
      }
      const Eigen::Matrix4d inv = bind.inverse();
      if (!FiniteMatrix(inv)) return Fail(kinemo::StrCat("bone ", nodes[static_cast<size_t>(node)]->mName.C_Str()), "bind pose is singular");
      for (int c = 0; c < 4; ++c) {
        for (int r = 0; r < 4; ++r) ibm.push_back(static_cast<float>(inv(r, c)));
      }
    }
    skin.inverseBindMatrices = AppendAccessor(model, ibm, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_MAT4,
                                              skin.joints.size(), 0);
    model.skins.push_back(skin);

    AddMaterials();
    KINEMO_RETURN_IF_ERROR(AddMeshes(mesh_node, parent, joint_of_node));

    tinygltf::Scene gscene;
    gscene.name = "Scene";
    gscene.nodes.push_back(0);
    for (size_t i = static_cast<size_t>(num_nodes); i < model.nodes.size(); ++i) gscene.nodes.push_back(static_cast<int>(i));
    model.scenes.push_back(gscene);
    model.defaultScene = 0;
    model.buffers[0].name = "fbx";

    auto src = std::make_shared<GltfSource>();
    src->path = name;
    src->format = "fbx";
    src->source_meters_per_unit = s;
    src->model = std::move(model);
    *out = std::move(src);
    return absl::OkStatus();
  }

  void AddMaterials() {
    for (unsigned i = 0; i < scene.mNumMaterials; ++i) {
      const aiMaterial* m = scene.mMaterials[i];
      tinygltf::Material mat;
      if (m == nullptr) {
        model.materials.push_back(mat);
        continue;
      }
      aiString mname;
      if (m->Get(AI_MATKEY_NAME, mname) == AI_SUCCESS) mat.name = mname.C_Str();
      aiColor4D diffuse(0.8f, 0.8f, 0.8f, 1.0f);
      m->Get(AI_MATKEY_COLOR_DIFFUSE, diffuse);
      float opacity = 1;
      m->Get(AI_MATKEY_OPACITY, opacity);
      auto unit = [](float v) { return std::isfinite(v) ? std::clamp(static_cast<double>(v), 0.0, 1.0) : 1.0; };
      mat.pbrMetallicRoughness.baseColorFactor = {unit(diffuse.r), unit(diffuse.g), unit(diffuse.b), unit(opacity)};
      mat.pbrMetallicRoughness.metallicFactor = 0;
      mat.pbrMetallicRoughness.roughnessFactor = 0.9;
      if (unit(opacity) < 1) mat.alphaMode = "BLEND";
      model.materials.push_back(mat);
    }
  }

  Status AddMeshes(const std::vector<int>& mesh_node, const std::vector<int>& parent,
                   const std::map<int, int>& joint_of_node) {
    for (unsigned m = 0; m < scene.mNumMeshes; ++m) {
      const aiMesh* mesh = scene.mMeshes[m];
      if (mesh_node[m] < 0 || mesh->mNumVertices == 0 || mesh->mNumFaces == 0 || mesh->mVertices == nullptr) continue;
      if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
      const std::string part = kinemo::StrCat("mesh ", mesh->mName.C_Str());
      const size_t nv = mesh->mNumVertices;
      const Eigen::Matrix4d world = Baked(raw_global[static_cast<size_t>(mesh_node[m])]);
      // Vertices in the file's units become metres: world · (s · v).
      auto point = [&](const aiVector3D& v) -> Eigen::Vector3d {
        return (world * Eigen::Vector4d(s * v.x, s * v.y, s * v.z, 1)).head<3>();
      };
      const Eigen::Matrix3d normal_matrix = world.block<3, 3>(0, 0).inverse().transpose();
      std::vector<float> pos(nv * 3), nrm, uv;
      for (size_t i = 0; i < nv; ++i) {
        const Eigen::Vector3d p = point(mesh->mVertices[i]);
        if (!p.allFinite()) return Fail(part, kinemo::StrCat("vertex ", i, " is not finite"));
        for (int c = 0; c < 3; ++c) pos[i * 3 + static_cast<size_t>(c)] = static_cast<float>(p[c]);
      }
      if (mesh->mNormals != nullptr) {
        nrm.resize(nv * 3);
        for (size_t i = 0; i < nv; ++i) {
          const aiVector3D& n = mesh->mNormals[i];
          Eigen::Vector3d v = normal_matrix * Eigen::Vector3d(n.x, n.y, n.z);
          v = v.allFinite() && v.norm() > 1e-12 ? Eigen::Vector3d(v.normalized()) : Eigen::Vector3d::UnitY();
          for (int c = 0; c < 3; ++c) nrm[i * 3 + static_cast<size_t>(c)] = static_cast<float>(v[c]);
        }
      }
      if (mesh->mTextureCoords[0] != nullptr) {
        uv.resize(nv * 2);
        for (size_t i = 0; i < nv; ++i) {
          const aiVector3D& t = mesh->mTextureCoords[0][i];
          uv[i * 2] = std::isfinite(t.x) ? t.x : 0;
          uv[i * 2 + 1] = std::isfinite(t.y) ? 1 - t.y : 0;  // glTF's v runs down
        }
      }
      std::vector<uint32_t> indices;
      indices.reserve(static_cast<size_t>(mesh->mNumFaces) * 3);
      for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
        const aiFace& face = mesh->mFaces[f];
        if (face.mNumIndices != 3) continue;  // points and lines are not drawn
        for (unsigned k = 0; k < 3; ++k) {
          if (face.mIndices[k] >= nv) return Fail(part, kinemo::StrCat("face ", f, " has a vertex out of range"));
          indices.push_back(face.mIndices[k]);
        }
      }
      if (indices.empty()) continue;
      // Up to four weights per vertex (aiProcess_LimitBoneWeights keeps
      // the largest four), normalised; a vertex no bone moves follows the
      // joint nearest above its mesh node, or the first joint.
      std::vector<std::array<std::pair<float, uint16_t>, 4>> influence(nv);
      std::vector<int> count(nv, 0);
      for (unsigned b = 0; b < mesh->mNumBones; ++b) {
        const aiBone* bone = mesh->mBones[b];
        const int joint = joint_of_node.at(node_of_name.at(bone->mName.C_Str()));
        for (unsigned w = 0; w < bone->mNumWeights; ++w) {
          const aiVertexWeight& vw = bone->mWeights[w];
          if (vw.mVertexId >= nv || !(vw.mWeight > 0) || !std::isfinite(vw.mWeight)) continue;
          auto& slots = influence[vw.mVertexId];
          int& n = count[vw.mVertexId];
          if (n < 4) {
            slots[static_cast<size_t>(n++)] = {vw.mWeight, static_cast<uint16_t>(joint)};
          } else {
            auto least = std::min_element(slots.begin(), slots.end());
            if (least->first < vw.mWeight) *least = {vw.mWeight, static_cast<uint16_t>(joint)};
          }
        }
      }
      int fallback = 0;
      for (int a = mesh_node[m]; a >= 0; a = parent[static_cast<size_t>(a)]) {
        if (auto it = joint_of_node.find(a); it != joint_of_node.end()) {
          fallback = it->second;
          break;
        }
      }
      std::vector<uint16_t> joints_attr(nv * 4, 0);
      std::vector<float> weights_attr(nv * 4, 0);
      for (size_t i = 0; i < nv; ++i) {
        float sum = 0;
        for (int k = 0; k < count[i]; ++k) sum += influence[i][static_cast<size_t>(k)].first;
        if (count[i] == 0 || !(sum > 0)) {
          joints_attr[i * 4] = static_cast<uint16_t>(fallback);
          weights_attr[i * 4] = 1;
          continue;
        }
        for (int k = 0; k < count[i]; ++k) {
          joints_attr[i * 4 + static_cast<size_t>(k)] = influence[i][static_cast<size_t>(k)].second;
          weights_attr[i * 4 + static_cast<size_t>(k)] = influence[i][static_cast<size_t>(k)].first / sum;
        }
      }

      tinygltf::Primitive prim;
      prim.mode = TINYGLTF_MODE_TRIANGLES;
      prim.attributes["POSITION"] = AppendAccessor(model, pos, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nv,
                                                   TINYGLTF_TARGET_ARRAY_BUFFER, true);
      if (!nrm.empty()) {
        prim.attributes["NORMAL"] = AppendAccessor(model, nrm, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nv,
                                                   TINYGLTF_TARGET_ARRAY_BUFFER);
      }
      if (!uv.empty()) {
        prim.attributes["TEXCOORD_0"] = AppendAccessor(model, uv, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2,
                                                       nv, TINYGLTF_TARGET_ARRAY_BUFFER);
      }
      prim.attributes["JOINTS_0"] = AppendAccessor(model, joints_attr, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
                                                   TINYGLTF_TYPE_VEC4, nv, TINYGLTF_TARGET_ARRAY_BUFFER);
      prim.attributes["WEIGHTS_0"] = AppendAccessor(model, weights_attr, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                                    TINYGLTF_TYPE_VEC4, nv, TINYGLTF_TARGET_ARRAY_BUFFER);
      prim.indices = AppendAccessor(model, indices, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR,
                                    indices.size(), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
      if (mesh->mMaterialIndex < model.materials.size()) prim.material = static_cast<int>(mesh->mMaterialIndex);

      // Blend shapes: morph targets (position deltas), named in extras.
      std::vector<tinygltf::Value> target_names;
      tinygltf::Mesh gmesh;
      gmesh.name = mesh->mName.C_Str();
      for (unsigned a = 0; a < mesh->mNumAnimMeshes; ++a) {
        const aiAnimMesh* am = mesh->mAnimMeshes[a];
        if (am == nullptr || am->mVertices == nullptr || am->mNumVertices != nv) continue;
        std::vector<float> delta(nv * 3);
        for (size_t i = 0; i < nv; ++i) {
          const Eigen::Vector3d d = point(am->mVertices[i]) -
                                    Eigen::Vector3d(pos[i * 3], pos[i * 3 + 1], pos[i * 3 + 2]);
          if (!d.allFinite()) return Fail(part, kinemo::StrCat("blend shape ", am->mName.C_Str(), " is not finite"));
          for (int c = 0; c < 3; ++c) delta[i * 3 + static_cast<size_t>(c)] = static_cast<float>(d[c]);
        }
        std::map<std::string, int> target;
        target["POSITION"] = AppendAccessor(model, delta, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nv,
                                            TINYGLTF_TARGET_ARRAY_BUFFER, true);
        prim.targets.push_back(target);
        target_names.emplace_back(std::string(am->mName.C_Str()));
        gmesh.weights.push_back(0);
      }
      if (!target_names.empty()) {
        tinygltf::Value::Object extras;
        extras["targetNames"] = tinygltf::Value(std::move(target_names));
        gmesh.extras = tinygltf::Value(std::move(extras));
      }
      gmesh.primitives.push_back(std::move(prim));
      model.meshes.push_back(std::move(gmesh));
      tinygltf::Node node;
      node.name = mesh->mName.C_Str();
      node.mesh = static_cast<int>(model.meshes.size()) - 1;
      node.skin = 0;
      model.nodes.push_back(node);
    }
    return absl::OkStatus();
  }
};

// assimp's FBX importer on bytes checked by CheckFbxStructure; the scene
// is owned by `importer`.
StatusOr<const aiScene*> Import(Assimp::Importer& importer, std::string_view bytes, const std::string& name) {
  importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_PRESERVE_PIVOTS, false);
  importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_READ_ANIMATIONS, false);
  importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_READ_CAMERAS, false);
  importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_READ_LIGHTS, false);
  importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_READ_TEXTURES, false);
  importer.SetPropertyInteger(AI_CONFIG_PP_LBW_MAX_WEIGHTS, 4);
  const aiScene* scene = importer.ReadFileFromMemory(
      bytes.data(), bytes.size(),
      aiProcess_Triangulate | aiProcess_LimitBoneWeights | aiProcess_JoinIdenticalVertices |
          aiProcess_ValidateDataStructure,
      "fbx");
  if (scene == nullptr || scene->mRootNode == nullptr) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": FBX: ", importer.GetErrorString()));
  }
  return scene;
}

// The scene's nodes in the order the glTF document numbers them (depth
// first, children in the file's order, the root first).
std::vector<aiNode*> NodesInOrder(aiNode* root) {
  std::vector<aiNode*> out;
  std::vector<aiNode*> stack = {root};
  while (!stack.empty()) {
    aiNode* n = stack.back();
    stack.pop_back();
    out.push_back(n);
    for (unsigned c = n->mNumChildren; c-- > 0;) {
      if (n->mChildren[c] != nullptr) stack.push_back(n->mChildren[c]);
    }
  }
  return out;
}

}  // namespace

bool IsFbxPath(std::string_view path) {
  if (path.size() < 4) return false;
  std::string ext(path.substr(path.size() - 4));
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".fbx";
}

StatusOr<std::shared_ptr<GltfSource>> ReadFbxFromMemory(std::string_view bytes, const std::string& name,
                                                        const FbxLimits& limits) {
  if (bytes.size() > limits.max_bytes) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": larger than ", limits.max_bytes >> 20, " MiB"));
  }
  if (!HasFbxHeader(bytes)) {
    return absl::InvalidArgumentError(
        kinemo::StrCat(name, ": not an FBX file (no \"Kaydara FBX Binary\" header, no FBXHeaderExtension)"));
  }
  KINEMO_RETURN_IF_ERROR(CheckFbxStructure(bytes, name));
  Assimp::Importer importer;
  KINEMO_ASSIGN_OR_RETURN(const aiScene* scene, Import(importer, bytes, name));
  double unit_cm = 1;  // FBX's UnitScaleFactor: centimetres per unit
  if (scene->mMetaData != nullptr) {
    double d = 0;
    float f = 0;
    if (scene->mMetaData->Get("UnitScaleFactor", d)) {
      unit_cm = d;
    } else if (scene->mMetaData->Get("UnitScaleFactor", f)) {
      unit_cm = f;
    }
  }
  if (!(unit_cm >= 1e-4 && unit_cm <= 1e6)) {
    return absl::InvalidArgumentError(kinemo::StrCat(name, ": GlobalSettings.UnitScaleFactor: must be in 1e-4..1e6 "
                                                           "centimetres per unit, got ", unit_cm));
  }
  Builder builder{*scene, name, limits};
  builder.s = unit_cm * 0.01;
  KINEMO_ASSIGN_OR_RETURN(builder.axes, AxisConversion(*scene, name));
  std::shared_ptr<GltfSource> out;
  KINEMO_RETURN_IF_ERROR(builder.Build(&out));
  return out;
}

StatusOr<std::shared_ptr<GltfSource>> ReadFbx(const std::string& path, const FbxLimits& limits) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return absl::NotFoundError(kinemo::StrCat(path, ": no such file"));
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec || size > limits.max_bytes) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": larger than ", limits.max_bytes >> 20, " MiB"));
  }
  std::string bytes(static_cast<size_t>(size), '\0');
  std::ifstream in(path, std::ios::binary);
  if (!in.read(bytes.data(), static_cast<std::streamsize>(size))) {
    return absl::NotFoundError(kinemo::StrCat(path, ": cannot read"));
  }
  return ReadFbxFromMemory(bytes, path, limits);
}

Status WriteAnimatedFbx(const Rig& rig, const motion::Clip& clip, const std::string& path) {
  if (!rig.gltf || rig.gltf->format != "fbx") {
    return absl::FailedPreconditionError(
        kinemo::StrCat(rig.name, ": FBX output needs an FBX rig (write .glb for other characters)"));
  }
  if (clip.skeleton.num_joints() != rig.skeleton.num_joints() ||
      clip.skeleton.num_channels() != rig.skeleton.num_channels()) {
    return absl::InvalidArgumentError("WriteAnimatedFbx: the clip is not on the rig's skeleton");
  }
  KINEMO_RETURN_IF_ERROR(clip.Validate());
  if (clip.num_frames() < 1) return absl::InvalidArgumentError("clip has no frames");
  const std::string& source = rig.gltf->path;
  std::string bytes;
  {
    std::error_code ec;
    const uintmax_t size = std::filesystem::file_size(source, ec);
    if (ec || size > FbxLimits{}.max_bytes) return absl::NotFoundError(kinemo::StrCat(source, ": cannot read again"));
    bytes.assign(static_cast<size_t>(size), '\0');
    std::ifstream in(source, std::ios::binary);
    if (!in.read(bytes.data(), static_cast<std::streamsize>(size))) {
      return absl::NotFoundError(kinemo::StrCat(source, ": cannot read again"));
    }
  }
  KINEMO_RETURN_IF_ERROR(CheckFbxStructure(bytes, source));
  Assimp::Importer importer;
  KINEMO_RETURN_IF_ERROR(Import(importer, bytes, source).status());
  std::unique_ptr<aiScene> scene(importer.GetOrphanedScene());
  const std::vector<aiNode*> nodes = NodesInOrder(scene->mRootNode);
  const tinygltf::Model& model = rig.gltf->model;
  const int nj = rig.skeleton.num_joints();
  for (int j = 0; j < nj; ++j) {
    const int node = rig.node[static_cast<size_t>(j)];
    if (node < 0 || static_cast<size_t>(node) >= nodes.size() || static_cast<size_t>(node) >= model.nodes.size() ||
        model.nodes[static_cast<size_t>(node)].name != nodes[static_cast<size_t>(node)]->mName.C_Str()) {
      return absl::FailedPreconditionError(kinemo::StrCat(source, ": changed since it was read"));
    }
  }
  KINEMO_ASSIGN_OR_RETURN(NodePoser poser, NodePoser::Create(rig));
  const double s = rig.gltf->source_meters_per_unit;
  const int nf = clip.num_frames();
  auto* anim = new aiAnimation;
  scene->mNumAnimations = 1;
  scene->mAnimations = new aiAnimation*[1]{anim};
  anim->mName = aiString(std::string("kinemo"));
  // assimp's exporter takes key times in seconds (whatever mTicksPerSecond says).
  anim->mTicksPerSecond = 1;
  anim->mDuration = (nf - 1) * clip.frame_time_s;
  anim->mNumChannels = static_cast<unsigned>(nj);
  anim->mChannels = new aiNodeAnim*[static_cast<size_t>(nj)];
  std::vector<int> translated_slot(static_cast<size_t>(nj), -1);
  for (size_t k = 0; k < poser.translated_joints().size(); ++k) translated_slot[static_cast<size_t>(poser.translated_joints()[k])] = static_cast<int>(k);
  for (int j = 0; j < nj; ++j) {
    const aiNode* n = nodes[static_cast<size_t>(rig.node[static_cast<size_t>(j)])];
    aiVector3D scale, position;
    aiQuaternion rotation;
    n->mTransformation.Decompose(scale, rotation, position);
    auto* ch = new aiNodeAnim;
    anim->mChannels[j] = ch;
    ch->mNodeName = n->mName;
    ch->mNumScalingKeys = 1;
    ch->mScalingKeys = new aiVectorKey[1];
    ch->mScalingKeys[0] = aiVectorKey(0.0, scale);
    ch->mNumRotationKeys = static_cast<unsigned>(nf);
    ch->mRotationKeys = new aiQuatKey[static_cast<size_t>(nf)];
    const bool moves = translated_slot[static_cast<size_t>(j)] >= 0;
    ch->mNumPositionKeys = moves ? static_cast<unsigned>(nf) : 1;
    ch->mPositionKeys = new aiVectorKey[moves ? static_cast<size_t>(nf) : 1];
    // The joint's bind translation (the file's units) when it does not move.
    const Eigen::Vector3d bind = poser.bind_translation()[static_cast<size_t>(j)] / s;
    ch->mPositionKeys[0] = aiVectorKey(0.0, aiVector3D(static_cast<ai_real>(bind.x()), static_cast<ai_real>(bind.y()),
                                                       static_cast<ai_real>(bind.z())));
  }
  std::vector<float> q(static_cast<size_t>(nj) * 4), t(poser.translated_joints().size() * 3);
  for (int f = 0; f < nf; ++f) {
    KINEMO_RETURN_IF_ERROR(poser.Pose(clip.frame(f), q, t));
    for (int j = 0; j < nj; ++j) {
      const float* r = &q[static_cast<size_t>(j) * 4];
      anim->mChannels[j]->mRotationKeys[f] = aiQuatKey(f * clip.frame_time_s, aiQuaternion(r[3], r[0], r[1], r[2]));
      if (const int k = translated_slot[static_cast<size_t>(j)]; k >= 0) {
        const float* p = &t[static_cast<size_t>(k) * 3];
        anim->mChannels[j]->mPositionKeys[f] = aiVectorKey(
            f * clip.frame_time_s, aiVector3D(static_cast<ai_real>(p[0] / s), static_cast<ai_real>(p[1] / s), static_cast<ai_real>(p[2] / s)));
      }
    }
  }
  Assimp::Exporter exporter;
  const aiExportDataBlob* blob = exporter.ExportToBlob(scene.get(), "fbx");
  if (blob == nullptr || blob->data == nullptr) {
    return absl::InternalError(kinemo::StrCat(path, ": assimp's FBX exporter: ", exporter.GetErrorString()));
  }
  // The source's axes and unit, the clip's frame rate (FBX TimeMode 14:
  // custom, CustomFrameRate).
  std::map<std::string, double> settings = {{"TimeMode", 14}, {"CustomFrameRate", 1.0 / clip.frame_time_s},
                                            {"UnitScaleFactor", s * 100}, {"OriginalUnitScaleFactor", s * 100}};
  if (scene->mMetaData != nullptr) {
    for (const char* key : {"UpAxis", "UpAxisSign", "FrontAxis", "FrontAxisSign", "CoordAxis", "CoordAxisSign"}) {
      int32_t v = 0;
      if (scene->mMetaData->Get(key, v)) settings[key] = v;
    }
  }
  KINEMO_ASSIGN_OR_RETURN(
      std::string fixed,
      FixExportedFbx(std::string_view(static_cast<const char*>(blob->data), blob->size), settings));
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out.write(fixed.data(), static_cast<std::streamsize>(fixed.size())) || !out.flush()) {
    return absl::PermissionDeniedError(kinemo::StrCat(path, ": cannot write"));
  }
  return absl::OkStatus();
}

}  // namespace kinemo::retarget
