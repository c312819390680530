#include "common/retarget/rig_info.h"

#include <algorithm>
#include <cctype>

#include "common/retarget/gltf.h"
#include "common/retarget/transform.h"

namespace kinemo::retarget {
namespace {

std::vector<std::string> MappedRoleNames(const Rig& rig) {
  std::vector<std::string> mapped;
  for (int r = 0; r < kNumRoles; ++r) {
    if (rig.roles.joint[static_cast<size_t>(r)] >= 0) mapped.emplace_back(RoleName(static_cast<Role>(r)));
  }
  return mapped;
}

nlohmann::json JawJson(const FaceMap& face) {
  const JawBone& jaw = face.jaw();
  if (jaw.joint < 0) return nullptr;
  return {{"name", jaw.name},
          {"found_by", jaw.found_by},
          {"hinge_axis", {jaw.hinge_axis.x(), jaw.hinge_axis.y(), jaw.hinge_axis.z()}},
          {"max_deg", jaw.max_deg}};
}

nlohmann::json ValueJson(const tinygltf::Value& v, int depth = 0) {
  if (depth > 8) return nullptr;
  if (v.IsBool()) return v.Get<bool>();
  if (v.IsNumber()) return v.GetNumberAsDouble();
  if (v.IsString()) return v.Get<std::string>();
  if (v.IsArray()) {
    nlohmann::json a = nlohmann::json::array();
    for (size_t i = 0; i < v.ArrayLen() && i < 64; ++i) a.push_back(ValueJson(Element(v, i), depth + 1));
    return a;
  }
  if (v.IsObject()) {
    nlohmann::json o = nlohmann::json::object();
    for (const std::string& k : v.Keys()) o[k] = ValueJson(v.Get(k), depth + 1);
    return o;
  }
  return nullptr;
}

}  // namespace

std::string RigFormat(const Rig& rig) {
  if (!rig.gltf) return "bvh";
  if (rig.gltf->format == "fbx") return "fbx";
  const tinygltf::Model& model = rig.gltf->model;
  if (model.extensions.count("VRMC_vrm")) return "vrm1";
  if (model.extensions.count("VRM")) return "vrm0";
  std::string ext = rig.gltf->path.size() >= 5 ? rig.gltf->path.substr(rig.gltf->path.size() - 5) : "";
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext == ".gltf" ? "gltf" : "glb";
}

nlohmann::json RigSummaryJson(const Rig& rig, const FaceMap& face) {
  return {{"format", RigFormat(rig)},
          {"family", std::string(RigFamilyName(rig.roles.family))},
          {"joints", rig.skeleton.num_joints()},
          {"mapped_roles", MappedRoleNames(rig)},
          {"unmapped_roles", rig.UnmappedRoles()},
          {"leg_length_m", rig.LegLength() * rig.meters_per_unit},
          {"face_channels_driven", face.num_driven()},
          {"mouth_family", face.mouth_family()},
          {"jaw_bone", face.jaw().joint >= 0 ? nlohmann::json(face.jaw().name) : nlohmann::json(nullptr)}};
}

nlohmann::json RigInfoJson(const Rig& rig, const FaceMap& face) {
  nlohmann::json out = RigSummaryJson(rig, face);
  out["name"] = rig.name;
  out["compression"] = rig.gltf ? rig.gltf->decoded : std::vector<std::string>();
  out["hips_height_m"] = rig.HipsHeight() * rig.meters_per_unit;
  nlohmann::json morphs = nlohmann::json::array();
  nlohmann::json channels = nlohmann::json::array();
  const std::vector<FaceControl>& controls = face.controls();
  std::string mesh;
  for (const FaceControl& c : controls) {
    if (c.kind == FaceControlKind::kMorphTarget) {
      if (morphs.empty() || morphs.back()["mesh"] != c.mesh) morphs.push_back({{"mesh", c.mesh}, {"targets", nlohmann::json::array()}});
      morphs.back()["targets"].push_back(c.name);
    }
    nlohmann::json ch = {{"kind", c.kind == FaceControlKind::kMorphTarget ? "morph_target" : "vrm_expression"},
                         {"name", c.name},
                         {"family", c.family},
                         {"group", c.group},
                         {"driven", c.driven()},
                         {"driven_by", c.DrivenBy(controls)}};
    if (c.kind == FaceControlKind::kMorphTarget) {
      ch["mesh"] = c.mesh;
      ch["target"] = c.target;
    } else {
      ch["vmc_name"] = c.vmc_name;
    }
    channels.push_back(std::move(ch));
  }
  out["morph_targets"] = morphs;
  out["face_channels"] = channels;
  out["jaw_bone"] = JawJson(face);
  out["jaw_full_open_deg"] = face.jaw_full_open_deg();
  out["vowel_open_deg"] = face.vowel_open_deg();
  if (rig.gltf) {
    const tinygltf::Model& model = rig.gltf->model;
    nlohmann::json expressions = nlohmann::json::array();
    for (const FaceControl& c : controls) {
      if (c.kind == FaceControlKind::kVrmExpression) expressions.push_back(c.name);
    }
    if (auto it = model.extensions.find("VRMC_vrm"); it != model.extensions.end()) {
      const tinygltf::Value& v = it->second;
      out["vrm"] = {{"spec_version", Member(v, "specVersion").IsString() ? Member(v, "specVersion").Get<std::string>() : ""},
                    {"expressions", expressions},
                    {"look_at", ValueJson(Member(v, "lookAt"))}};
    } else if (auto it0 = model.extensions.find("VRM"); it0 != model.extensions.end()) {
      const tinygltf::Value& v = it0->second;
      const tinygltf::Value& fp = Member(v, "firstPerson");
      out["vrm"] = {{"spec_version", Member(v, "specVersion").IsString() ? Member(v, "specVersion").Get<std::string>() : "0.0"},
                    {"expressions", expressions},
                    {"look_at", {{"type", ValueJson(Member(fp, "lookAtTypeName"))},
                                 {"offset_from_head_bone", ValueJson(Member(fp, "firstPersonBoneOffset"))}}}};
    }
  }
  return out;
}

}  // namespace kinemo::retarget
