#include "common/retarget/rig.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "common/motion/kinematics.h"
#include "common/retarget/gltf.h"
#include "common/retarget/transform.h"

namespace kinemo::retarget {
namespace {

using motion::ChannelType;

std::vector<ChannelType> RotationChannels(bool with_position) {
  std::vector<ChannelType> c;
  if (with_position) c = {ChannelType::kXPosition, ChannelType::kYPosition, ChannelType::kZPosition};
  c.insert(c.end(), {ChannelType::kZRotation, ChannelType::kXRotation, ChannelType::kYRotation});
  return c;
}

// Rebuilds a skeleton in the world-aligned rest convention from names,
// parents (preceding) and rest world positions; position channels on roots
// and on `hips`.
StatusOr<motion::Skeleton> BuildRestSkeleton(const std::vector<std::string>& names, const std::vector<int>& parents,
                                             const std::vector<Eigen::Vector3d>& positions, int hips) {
  std::vector<motion::Joint> joints(names.size());
  for (size_t j = 0; j < names.size(); ++j) {
    motion::Joint& joint = joints[j];
    joint.name = names[j];
    joint.parent = parents[j];
    joint.offset = parents[j] < 0 ? positions[j] : Eigen::Vector3d(positions[j] - positions[parents[j]]);
    joint.channels = RotationChannels(parents[j] < 0 || static_cast<int>(j) == hips);
  }
  // End sites for leaf joints: a short stub along the parent bone, so BVH
  // viewers draw the last bone.
  std::vector<int> children(names.size(), 0);
  for (int p : parents) {
    if (p >= 0) ++children[p];
  }
  for (size_t j = 0; j < names.size(); ++j) {
    if (children[j] == 0) joints[j].end_site = parents[j] >= 0 ? Eigen::Vector3d(joints[j].offset * 0.1)
                                                               : Eigen::Vector3d(0, 0.1, 0);
  }
  return motion::Skeleton::Create(std::move(joints));
}

StatusOr<RoleMap> ChooseRoleMap(const std::vector<std::string>& names, const RoleMapChoice& choice,
                                std::optional<RoleMap> builtin) {
  if (!choice.map_json.empty()) {
    KINEMO_ASSIGN_OR_RETURN(RoleNames rn, ParseRoleMapJson(choice.map_json, choice.map_source));
    return ApplyRoleNames(rn, names, choice.map_source);
  }
  if (builtin) return *builtin;
  return DetectRoleMap(names);
}

// VRM humanBones name -> role. The thumbs differ by version: VRM 0.x names
// its three thumb bones Proximal, Intermediate, Distal; VRM 1.0 Metacarpal,
// Proximal, Distal (the VRM 1.0 migration maps 0.x Proximal to Metacarpal).
std::optional<Role> VrmBoneRole(std::string_view bone, bool vrm0) {
  using namespace roles;
  static const std::map<std::string, Role, std::less<>> kCore = {
      {"hips", kHips}, {"spine", kSpine}, {"chest", kChest}, {"upperChest", kUpperChest},
      {"neck", kNeck}, {"head", kHead},   {"jaw", kJaw}};
  if (auto it = kCore.find(bone); it != kCore.end()) return it->second;
  int side = -1;
  std::string_view rest;
  if (bone.starts_with("left")) {
    side = 0;
    rest = bone.substr(4);
  } else if (bone.starts_with("right")) {
    side = 1;
    rest = bone.substr(5);
  } else {
    return std::nullopt;
  }
  static const std::map<std::string, int, std::less<>> kLimb = {
      {"Shoulder", kShoulder}, {"UpperArm", kUpperArm}, {"LowerArm", kForearm}, {"Hand", kHand},
      {"UpperLeg", kThigh},    {"LowerLeg", kShin},     {"Foot", kFoot},        {"Toes", kToes}};
  if (auto it = kLimb.find(rest); it != kLimb.end()) return Side(side, it->second);
  if (vrm0 && rest == "ThumbProximal") return Finger(side, 0, 0);
  static const std::map<std::string, std::pair<int, int>, std::less<>> kFinger = {
      {"ThumbMetacarpal", {0, 0}},     {"ThumbProximal", {0, 1}},       {"ThumbIntermediate", {0, 1}},
      {"ThumbDistal", {0, 2}},         {"IndexProximal", {1, 0}},       {"IndexIntermediate", {1, 1}},
      {"IndexDistal", {1, 2}},         {"MiddleProximal", {2, 0}},      {"MiddleIntermediate", {2, 1}},
      {"MiddleDistal", {2, 2}},        {"RingProximal", {3, 0}},        {"RingIntermediate", {3, 1}},
      {"RingDistal", {3, 2}},          {"LittleProximal", {4, 0}},      {"LittleIntermediate", {4, 1}},
      {"LittleDistal", {4, 2}}};
  if (auto it = kFinger.find(rest); it != kFinger.end()) return Finger(side, it->second.first, it->second.second);
  return std::nullopt;
}

// The VRM humanoid of a document as node -> role (`*is_vrm` false when the
// document is not a VRM); `*bone_names` gets role -> the VRM bone name.
// INVALID_ARGUMENT naming the part for a bone whose node is not a node.
StatusOr<std::map<int, Role>> VrmHumanBones(const tinygltf::Model& model, bool* is_vrm,
                                            std::map<Role, std::string>* bone_names) {
  std::map<int, Role> out;
  *is_vrm = false;
  const int num_nodes = static_cast<int>(model.nodes.size());
  bool vrm0 = false;
  auto add = [&](const std::string& bone, const tinygltf::Value& node, const std::string& part) -> Status {
    if (!node.IsNumber()) return InvalidField(part, "has no node index");
    const double n = node.GetNumberAsDouble();
    if (!(n >= 0 && n < num_nodes) || n != std::floor(n)) return InvalidField(part, "node ", n, " is not a node of the file");
    const std::optional<Role> role = VrmBoneRole(bone, vrm0);
    if (role) {
      if (out.count(static_cast<int>(n))) return InvalidField(part, "node ", n, " is already another bone");
      out[static_cast<int>(n)] = *role;
      (*bone_names)[*role] = bone;
    }
    return absl::OkStatus();
  };
  if (auto it = model.extensions.find("VRMC_vrm"); it != model.extensions.end()) {  // 1.0
    const tinygltf::Value& bones = Member(Member(it->second, "humanoid"), "humanBones");
    if (!bones.IsObject()) return InvalidField("extensions.VRMC_vrm.humanoid.humanBones", "missing or not an object");
    *is_vrm = true;
    for (const std::string& key : bones.Keys()) {
      KINEMO_RETURN_IF_ERROR(add(key, Member(Member(bones, key), "node"),
                                 kinemo::StrCat("extensions.VRMC_vrm.humanoid.humanBones.", key, ".node")));
    }
  } else if (auto it0 = model.extensions.find("VRM"); it0 != model.extensions.end()) {  // 0.x
    const tinygltf::Value& bones = Member(Member(it0->second, "humanoid"), "humanBones");
    if (!bones.IsArray()) return InvalidField("extensions.VRM.humanoid.humanBones", "missing or not an array");
    *is_vrm = true;
    vrm0 = true;
    for (size_t i = 0; i < bones.ArrayLen(); ++i) {
      const tinygltf::Value& b = Element(bones, i);
      if (!Member(b, "bone").IsString()) continue;
      KINEMO_RETURN_IF_ERROR(add(Member(b, "bone").Get<std::string>(), Member(b, "node"),
                                 kinemo::StrCat("extensions.VRM.humanoid.humanBones[", i, "].node")));
    }
  }
  return out;
}

// A VRM without a skin (a humanoid of plain nodes, e.g. the VRM
// consortium's feature-test models): its joints are the humanoid's bones
// and the nodes between them, in the node default pose (VRM's rest pose).
std::vector<int> HumanoidNodes(const std::map<int, Role>& bones, const NodeTree& tree) {
  std::set<int> out;
  for (const auto& [node, role] : bones) {
    out.insert(node);
    // Up to the next bone: the nodes between two bones are joints too.
    std::vector<int> path;
    for (int a = tree.parent[node]; a >= 0; a = tree.parent[a]) {
      if (bones.count(a)) {
        out.insert(path.begin(), path.end());
        break;
      }
      path.push_back(a);
    }
  }
  return {out.begin(), out.end()};
}

}  // namespace

Eigen::Matrix4d SkinBindSpace(const tinygltf::Model& model, const NodeTree& tree, int skin_index,
                              const std::vector<int>& skin_joints, const std::vector<Eigen::Matrix4d>& ibm,
                              int top_joint_node, int mesh_node) {
  const int num_nodes = static_cast<int>(model.nodes.size());
  Eigen::Matrix4d bind_space = Eigen::Matrix4d::Identity();
  bool have_space = false;
  if (mesh_node >= 0 && mesh_node < num_nodes) {
    bind_space = tree.global[static_cast<size_t>(mesh_node)];
    have_space = true;
  }
  for (int n = 0; n < num_nodes && !have_space; ++n) {
    if (skin_index >= 0 && model.nodes[n].skin == skin_index && model.nodes[n].mesh >= 0) {
      bind_space = tree.global[n];
      have_space = true;
    }
  }
  if (!have_space && top_joint_node >= 0 && tree.parent[top_joint_node] >= 0) {
    bind_space = tree.global[tree.parent[top_joint_node]];
  }
  // When most joints' default pose is their bind pose, that pose says what
  // the space is: joint world × inverse bind matrix is then one matrix for
  // all of them. It differs from the mesh node's world when a tool folded a
  // transform into the inverse bind matrices (gltfpack / glTF-Transform
  // quantization puts the positions' dequantization there: the VALID
  // avatars' skeleton would otherwise come out 1/100 of its size).
  if (!ibm.empty()) {
    const size_t n = skin_joints.size();
    std::vector<Eigen::Matrix4d> space(n);
    for (size_t k = 0; k < n && k < ibm.size(); ++k) space[k] = tree.global[static_cast<size_t>(skin_joints[k])] * ibm[k];
    // The topmost joint (the skeleton's root) is where a posed default
    // (arms down, robot_expressive.glb) least often differs from the bind.
    size_t top = 0;
    for (size_t k = 0; k < n; ++k) {
      if (tree.depth[static_cast<size_t>(skin_joints[k])] < tree.depth[static_cast<size_t>(skin_joints[top])]) top = k;
    }
    size_t best = 0, best_count = 0;
    bool best_has_top = false;
    const size_t step = std::max<size_t>(1, n / 32);  // candidates: at most ~32, and the top
    for (size_t c = 0; c <= n; c += step) {
      const size_t cand = c < n ? c : top;
      const double tol = 1e-3 * std::max(1e-12, space[cand].cwiseAbs().maxCoeff());
      size_t count = 0;
      bool has_top = false;
      for (size_t k = 0; k < n; ++k) {
        if ((space[k] - space[cand]).cwiseAbs().maxCoeff() <= tol) {
          ++count;
          has_top = has_top || k == top;
        }
      }
      if (count > best_count) {
        best = cand;
        best_count = count;
        best_has_top = has_top;
      }
      if (c >= n) break;
    }
    // Trusted when most joints agree, or a few do with the root among them.
    const double agree = 1e-3 * std::max(1e-12, bind_space.cwiseAbs().maxCoeff());
    if (best_count >= 2 && (2 * best_count >= n || best_has_top) &&
        (space[best] - bind_space).cwiseAbs().maxCoeff() > agree) {
      bind_space = space[best];
    }
  }

  return bind_space;
}

std::vector<Eigen::Vector3d> Rig::RestPositions() const {
  std::vector<Eigen::Vector3d> p(static_cast<size_t>(skeleton.num_joints()));
  for (int j = 0; j < skeleton.num_joints(); ++j) {
    const motion::Joint& joint = skeleton.joint(j);
    p[j] = joint.parent < 0 ? joint.offset : Eigen::Vector3d(p[joint.parent] + joint.offset);
  }
  return p;
}

double Rig::LegLength() const {
  using namespace roles;
  const std::vector<Eigen::Vector3d> p = RestPositions();
  double sum = 0;
  int legs = 0;
  for (int side = 0; side < 2; ++side) {
    const int hip = roles.joint[Side(side, kThigh)], knee = roles.joint[Side(side, kShin)],
              ankle = roles.joint[Side(side, kFoot)];
    if (hip < 0 || knee < 0 || ankle < 0) continue;
    sum += (p[knee] - p[hip]).norm() + (p[ankle] - p[knee]).norm();
    ++legs;
  }
  return legs ? sum / legs : 0;
}

double Rig::HipsHeight() const {
  using namespace roles;
  const std::vector<Eigen::Vector3d> p = RestPositions();
  const int hips = roles.joint[kHips];
  if (hips < 0) return 0;
  // A rest pose that does not stand (Bandai's zero pose lies on its back):
  // the legs' length plus a tenth for the pelvis and the foot.
  const int head = roles.joint[kHead];
  if (head >= 0 && (p[head] - p[hips]).normalized().y() < 0.7) return 1.1 * LegLength();
  double lowest = p[hips].y();
  for (int side = 0; side < 2; ++side) {
    for (int b : {kFoot, kToes}) {
      const int j = roles.joint[Side(side, b)];
      if (j < 0) continue;
      lowest = std::min(lowest, p[j].y());
      if (skeleton.joint(j).end_site) lowest = std::min(lowest, p[j].y() + skeleton.joint(j).end_site->y());
    }
  }
  // glTF characters stand on y = 0 (their ankles are above it); a BVH rest
  // pose may hang below the origin (SMPL-X: pelvis at 0).
  return p[hips].y() - std::min(lowest, 0.0);
}

RestAxes Rig::RestBodyAxes() const {
  using namespace roles;
  const std::vector<Eigen::Vector3d> p = RestPositions();
  RestAxes axes;
  const int hips = roles.joint[kHips], head = roles.joint[kHead];
  if (hips < 0 || head < 0) return axes;
  Eigen::Vector3d up = Eigen::Vector3d::UnitY();
  if ((p[head] - p[hips]).normalized().y() < 0.7) {
    const int top = roles.joint[kNeck] >= 0 ? roles.joint[kNeck] : head;
    up = (p[top] - p[hips]).normalized();
  }
  auto frame = [&](int left_joint, int right_joint) {
    Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
    Eigen::Vector3d left = left_joint >= 0 && right_joint >= 0 ? Eigen::Vector3d(p[left_joint] - p[right_joint])
                                                               : Eigen::Vector3d::UnitX();
    left -= left.dot(up) * up;
    if (left.norm() < 1e-9) left = up.unitOrthogonal();
    left.normalize();
    f.col(0) = left;
    f.col(1) = up;
    f.col(2) = left.cross(up);
    return f;
  };
  axes.pelvis = frame(roles.joint[Side(0, kThigh)], roles.joint[Side(1, kThigh)]);
  axes.upper = frame(roles.joint[Side(0, kUpperArm)], roles.joint[Side(1, kUpperArm)]);
  return axes;
}

std::vector<std::string> Rig::UnmappedRoles() const {
  std::vector<std::string> out;
  for (int r = 0; r < kNumRoles; ++r) {
    if (roles.joint[r] < 0) out.emplace_back(RoleName(r));
  }
  return out;
}

double EstimateMetersPerUnit(const Rig& rig) {
  const double leg = rig.LegLength();
  if (!(leg > 0)) return 0.01;
  const double guess = 0.8 / leg;
  double best = 1;
  for (double unit : {1.0, 0.1, 0.0254, 0.01, 0.001}) {
    if (std::abs(std::log(unit / guess)) < std::abs(std::log(best / guess))) best = unit;
  }
  return best;
}

Status CheckRequiredRoles(const Rig& rig) {
  const std::vector<std::string> missing = MissingRequiredRoles(rig.roles.joint);
  if (missing.empty()) return absl::OkStatus();
  std::string list;
  for (const std::string& r : missing) list += (list.empty() ? "" : ", ") + r;
  return absl::InvalidArgumentError(kinemo::StrCat(rig.name, ": the rig lacks required roles: ", list,
                                                   " (map them with --map {\"role\": \"joint\"})"));
}

StatusOr<Rig> RigFromSkeleton(const motion::Skeleton& skeleton, double meters_per_unit, std::string name,
                              const RoleMapChoice& choice) {
  if (!(meters_per_unit > 0) || !std::isfinite(meters_per_unit)) {
    return InvalidField("meters_per_unit", "must be positive, got ", meters_per_unit);
  }
  std::vector<std::string> names;
  std::vector<int> parents;
  for (const motion::Joint& j : skeleton.joints()) {
    names.push_back(j.name);
    parents.push_back(j.parent);
  }
  Rig rig;
  rig.name = std::move(name);
  KINEMO_ASSIGN_OR_RETURN(rig.roles, ChooseRoleMap(names, choice, std::nullopt));
  // Rest pose: zero rotations, every joint at its OFFSET (also where
  // position channels would replace it: Bandai has them on every joint).
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(skeleton.num_joints()));
  for (int j = 0; j < skeleton.num_joints(); ++j) {
    const motion::Joint& joint = skeleton.joint(j);
    pos[j] = joint.parent < 0 ? joint.offset : Eigen::Vector3d(pos[joint.parent] + joint.offset);
  }
  KINEMO_ASSIGN_OR_RETURN(rig.skeleton, BuildRestSkeleton(names, parents, pos, rig.roles.joint[roles::kHips]));
  // Keep the source's end sites (BuildRestSkeleton guesses them).
  std::vector<motion::Joint> joints(rig.skeleton.joints().begin(), rig.skeleton.joints().end());
  for (int j = 0; j < skeleton.num_joints(); ++j) joints[j].end_site = skeleton.joint(j).end_site;
  KINEMO_ASSIGN_OR_RETURN(rig.skeleton, motion::Skeleton::Create(std::move(joints)));
  rig.meters_per_unit = meters_per_unit;
  rig.bind_rotation.assign(pos.size(), Eigen::Matrix3d::Identity());
  rig.node.assign(pos.size(), -1);
  KINEMO_RETURN_IF_ERROR(CheckRequiredRoles(rig));
  return rig;
}

StatusOr<Rig> LoadGltfRig(const std::string& path, const RoleMapChoice& choice) {
  KINEMO_ASSIGN_OR_RETURN(std::shared_ptr<GltfSource> src, ReadGltf(path));
  return RigFromGltf(std::move(src), choice);
}

StatusOr<Rig> RigFromGltf(std::shared_ptr<const GltfSource> src, const RoleMapChoice& choice) {
  const std::string& path = src->path;
  const tinygltf::Model& model = src->model;
  const int num_nodes = static_cast<int>(model.nodes.size());
  auto built = BuildNodeTree(model);
  if (!built.ok()) return Annotate(built.status(), path);
  const NodeTree& tree = *built;
  bool is_vrm = false;
  std::map<Role, std::string> vrm_bone_names;
  auto vrm_bones = VrmHumanBones(model, &is_vrm, &vrm_bone_names);
  if (!vrm_bones.ok()) return Annotate(vrm_bones.status(), path);
  const std::map<int, Role>& vrm = *vrm_bones;
  // The skin with the most joints; a VRM without a skin: its humanoid nodes.
  int skin_index = -1;
  for (size_t s = 0; s < model.skins.size(); ++s) {
    if (skin_index < 0 || model.skins[s].joints.size() > model.skins[static_cast<size_t>(skin_index)].joints.size()) {
      skin_index = static_cast<int>(s);
    }
  }
  std::vector<int> skin_joints;
  std::vector<Eigen::Matrix4d> ibm;
  if (skin_index >= 0) {
    const tinygltf::Skin& skin = model.skins[static_cast<size_t>(skin_index)];
    for (int n : skin.joints) {
      if (n < 0 || n >= num_nodes) return InvalidField(kinemo::StrCat(path, ": skins[", skin_index, "].joints"), "node ", n, " out of range");
    }
    skin_joints = skin.joints;
    auto read = ReadInverseBindMatrices(model, skin);
    if (!read.ok()) return Annotate(read.status(), path);
    ibm = *std::move(read);
  } else if (is_vrm && !vrm.empty()) {
    skin_joints = HumanoidNodes(vrm, tree);
  } else {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": no skin (not a rigged character)"));
  }
  // A VRM names its humanoid: a required bone it lacks is named as VRM names it.
  if (is_vrm && choice.map_json.empty()) {
    static constexpr std::pair<Role, const char*> kRequired[] = {
        {roles::kHips, "hips"}, {roles::kHead, "head"},
        {roles::Side(0, roles::kUpperArm), "leftUpperArm"}, {roles::Side(1, roles::kUpperArm), "rightUpperArm"},
        {roles::Side(0, roles::kForearm), "leftLowerArm"}, {roles::Side(1, roles::kForearm), "rightLowerArm"},
        {roles::Side(0, roles::kThigh), "leftUpperLeg"}, {roles::Side(1, roles::kThigh), "rightUpperLeg"},
        {roles::Side(0, roles::kShin), "leftLowerLeg"}, {roles::Side(1, roles::kShin), "rightLowerLeg"}};
    std::string missing;
    for (const auto& [role, bone] : kRequired) {
      if (!vrm_bone_names.count(role)) missing += kinemo::StrCat(missing.empty() ? "" : ", ", bone);
    }
    if (!vrm_bone_names.count(roles::kSpine) && !vrm_bone_names.count(roles::kChest) &&
        !vrm_bone_names.count(roles::kUpperChest)) {
      missing += kinemo::StrCat(missing.empty() ? "" : ", ", "spine");
    }
    if (!missing.empty()) {
      return absl::InvalidArgumentError(kinemo::StrCat(
          path, ": extensions.", model.extensions.count("VRMC_vrm") ? "VRMC_vrm" : "VRM",
          ".humanoid.humanBones: the humanoid lacks required bones: ", missing));
    }
  }

  // Joints ordered by node depth (parents first), each joint's parent the
  // nearest ancestor node that is a joint.
  std::vector<int> order(skin_joints.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return tree.depth[skin_joints[a]] < tree.depth[skin_joints[b]]; });
  std::map<int, int> joint_of_node;  // node -> our joint index
  for (size_t j = 0; j < order.size(); ++j) {
    if (!joint_of_node.emplace(skin_joints[order[j]], static_cast<int>(j)).second) {
      return InvalidField(kinemo::StrCat(path, ": skins[", skin_index, "].joints"), "node ", skin_joints[order[j]], " is listed twice");
    }
  }

  const Eigen::Matrix4d bind_space =
      SkinBindSpace(model, tree, skin_index, skin_joints, ibm, order.empty() ? -1 : skin_joints[order[0]]);

  std::vector<std::string> names;
  std::vector<int> parents;
  std::vector<Eigen::Vector3d> positions;
  Rig rig;
  rig.name = std::filesystem::path(path).filename().string();
  std::map<std::string, int> seen;
  for (size_t j = 0; j < order.size(); ++j) {
    const int node = skin_joints[order[j]];
    std::string name = model.nodes[node].name.empty() ? kinemo::StrCat("node", node) : model.nodes[node].name;
    if (seen[name]++ > 0) name = kinemo::StrCat(name, "#", node);  // duplicate names (robot_expressive)
    names.push_back(name);
    int parent = -1;
    for (int a = tree.parent[node]; a >= 0; a = tree.parent[a]) {
      if (auto it = joint_of_node.find(a); it != joint_of_node.end()) {
        parent = it->second;
        break;
      }
    }
    parents.push_back(parent);
    const Eigen::Matrix4d bind =
        ibm.empty() ? tree.global[node] : Eigen::Matrix4d(bind_space * ibm[order[j]].inverse());
    positions.push_back(bind.block<3, 1>(0, 3));
    rig.bind_rotation.push_back(Orthonormalized(bind.block<3, 3>(0, 0)));
    rig.node.push_back(node);
  }
  std::optional<RoleMap> builtin;
  if (is_vrm) {
    RoleMap m;
    m.family = RigFamily::kVrm;
    for (const auto& [node, role] : vrm) {
      if (auto it = joint_of_node.find(node); it != joint_of_node.end()) m.joint[role] = it->second;
    }
    builtin = m;
  }
  {
    // A skeleton no built-in map fits is the file's fault: named as such.
    auto chosen = ChooseRoleMap(names, choice, builtin);
    if (!chosen.ok() && chosen.status().code() == absl::StatusCode::kNotFound) {
      return absl::InvalidArgumentError(kinemo::StrCat(path, ": skeleton: ", chosen.status().message()));
    }
    KINEMO_ASSIGN_OR_RETURN(rig.roles, std::move(chosen));
  }
  KINEMO_ASSIGN_OR_RETURN(rig.skeleton, BuildRestSkeleton(names, parents, positions, rig.roles.joint[roles::kHips]));
  // A leaf joint's end site: its first child node that is no joint, no mesh
  // and has no children (Blender's "Foot.L_end"), placed by the bind pose.
  {
    std::vector<motion::Joint> joints(rig.skeleton.joints().begin(), rig.skeleton.joints().end());
    bool changed = false;
    for (size_t j = 0; j < joints.size(); ++j) {
      if (!rig.skeleton.children(static_cast<int>(j)).empty()) continue;
      for (int c : model.nodes[rig.node[j]].children) {
        if (joint_of_node.count(c) || model.nodes[c].mesh >= 0 || !model.nodes[c].children.empty() ||
            (ibm.empty() && skin_index >= 0)) {
          continue;
        }
        const Eigen::Matrix4d bind = ibm.empty() ? tree.global[c]
                                                 : Eigen::Matrix4d(bind_space * ibm[order[j]].inverse() *
                                                                   NodeLocalMatrix(model.nodes[c]));
        joints[j].end_site = Eigen::Vector3d(bind.block<3, 1>(0, 3) - positions[j]);
        changed = true;
        break;
      }
    }
    // The feet: a character's bind pose stands on y = 0, and its foot bones
    // run from the ankle to the toes inside the shoe, well above the sole.
    // The foot's end site is put on the floor under the toe tip, so that
    // the sole (feet.h) is where the shoe touches the ground.
    for (int side = 0; side < 2; ++side) {
      int foot = rig.roles.joint[roles::Side(side, roles::kToes)];
      if (foot < 0) foot = rig.roles.joint[roles::Side(side, roles::kFoot)];
      if (foot < 0 || !rig.skeleton.children(foot).empty()) continue;
      const double ankle_y = positions[foot].y();
      Eigen::Vector3d end = joints[foot].end_site.value_or(Eigen::Vector3d::Zero());
      // (A toe joint on the floor itself, as in VRM's test humanoids: its
      // end site is levelled onto the floor rather than below it.)
      const bool on_floor = std::abs(ankle_y) <= 1e-3;
      if (!on_floor && (ankle_y <= 0 || ankle_y > 0.3 || ankle_y + end.y() < 0)) continue;
      end.y() = -ankle_y;
      joints[foot].end_site = end;
      changed = true;
    }
    if (changed) {
      KINEMO_ASSIGN_OR_RETURN(rig.skeleton, motion::Skeleton::Create(std::move(joints)));
    }
  }
  rig.meters_per_unit = 1;
  rig.gltf = std::move(src);
  KINEMO_RETURN_IF_ERROR(CheckRequiredRoles(rig));
  return rig;
}

}  // namespace kinemo::retarget
