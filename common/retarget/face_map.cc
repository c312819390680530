// The face map (face_map.h): a rig's morph targets, VRM expressions and
// jaw found and turned into controls driven by face frames. The tables of
// morph-name families (OVR, ARKit, Rocketbox, VRM, plain names) are in
// face_names.cc.
#include "common/retarget/face_map.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "common/json/json_fields.h"
#include "common/motion/kinematics.h"
#include "common/retarget/face_names.h"
#include "common/retarget/gltf.h"
#include "common/retarget/transform.h"
#include "common/retarget/gltf_decode.h"

namespace kinemo::retarget {
namespace {

constexpr std::array<std::string_view, kNumFaceInputs> kInputNames = {
    "sil", "PP", "FF", "TH", "DD", "kk", "CH", "SS", "nn", "RR", "aa", "E", "ih", "oh", "ou",
    "jaw", "blink_left", "blink_right", "brow_raise", "happy", "angry", "sad", "surprised"};

// A VRM expression read from the file, before it becomes a control.
struct VrmExpression {
  std::string name, vmc_name;
  bool binary = false;
  std::vector<std::pair<std::pair<int, int>, float>> binds;  // (mesh, target) -> weight 0..1
  bool other_binds = false;  // material / texture binds (applied by VRM runtimes only)
};

StatusOr<std::vector<VrmExpression>> ReadVrmExpressions(const tinygltf::Model& model,
                                                        const std::vector<int>& targets_of_mesh) {
  std::vector<VrmExpression> out;
  auto check = [&](int mesh, int target, const std::string& part) -> Status {
    if (mesh < 0 || mesh >= static_cast<int>(targets_of_mesh.size())) return InvalidField(part, "mesh ", mesh, " out of range");
    if (target < 0 || target >= targets_of_mesh[static_cast<size_t>(mesh)]) {
      return InvalidField(part, "morph target ", target, " out of range (mesh ", mesh, " has ",
                          targets_of_mesh[static_cast<size_t>(mesh)], ")");
    }
    return absl::OkStatus();
  };
  auto number = [](const tinygltf::Value& v, double fallback) { return v.IsNumber() ? v.GetNumberAsDouble() : fallback; };
  if (auto it = model.extensions.find("VRMC_vrm"); it != model.extensions.end()) {
    const tinygltf::Value& expressions = Member(it->second, "expressions");
    for (const char* kind : {"preset", "custom"}) {
      const tinygltf::Value& set = Member(expressions, kind);
      if (!set.IsObject()) continue;
      for (const std::string& key : set.Keys()) {
        const tinygltf::Value& e = Member(set, key);
        const std::string part = kinemo::StrCat("extensions.VRMC_vrm.expressions.", kind, ".", key);
        VrmExpression x;
        x.name = key;
        x.vmc_name = key;
        x.binary = Member(e, "isBinary").IsBool() && Member(e, "isBinary").Get<bool>();
        const tinygltf::Value& binds = Member(e, "morphTargetBinds");
        for (size_t b = 0; binds.IsArray() && b < binds.ArrayLen(); ++b) {
          const tinygltf::Value& bind = Element(binds, b);
          const std::string bpart = kinemo::StrCat(part, ".morphTargetBinds[", b, "]");
          const double node = number(Member(bind, "node"), -1), index = number(Member(bind, "index"), -1);
          if (!(node >= 0 && node < static_cast<double>(model.nodes.size()))) return InvalidField(bpart, "node out of range");
          const int mesh = model.nodes[static_cast<size_t>(node)].mesh;
          if (mesh < 0) return InvalidField(bpart, "node ", node, " has no mesh");
          if (!(index >= 0 && index < 1e6)) return InvalidField(bpart, "index out of range");
          KINEMO_RETURN_IF_ERROR(check(mesh, static_cast<int>(index), bpart));
          const double w = std::clamp(number(Member(bind, "weight"), 0), 0.0, 1.0);
          x.binds.push_back({{mesh, static_cast<int>(index)}, static_cast<float>(w)});
        }
        x.other_binds = (Member(e, "materialColorBinds").IsArray() && Member(e, "materialColorBinds").ArrayLen() > 0) ||
                        (Member(e, "textureTransformBinds").IsArray() && Member(e, "textureTransformBinds").ArrayLen() > 0);
        out.push_back(std::move(x));
      }
    }
  } else if (auto it0 = model.extensions.find("VRM"); it0 != model.extensions.end()) {
    const tinygltf::Value& groups = Member(Member(it0->second, "blendShapeMaster"), "blendShapeGroups");
    for (size_t g = 0; groups.IsArray() && g < groups.ArrayLen(); ++g) {
      const tinygltf::Value& group = Element(groups, g);
      const std::string part = kinemo::StrCat("extensions.VRM.blendShapeMaster.blendShapeGroups[", g, "]");
      const std::string preset = Member(group, "presetName").IsString() ? face_names::Lower(Member(group, "presetName").Get<std::string>()) : "";
      const std::string group_name = Member(group, "name").IsString() ? Member(group, "name").Get<std::string>() : "";
      VrmExpression x;
      x.name = preset.empty() || preset == "unknown" ? group_name : preset;
      if (x.name.empty()) continue;
      x.vmc_name = face_names::Vrm0VmcName(preset, group_name);
      x.binary = Member(group, "isBinary").IsBool() && Member(group, "isBinary").Get<bool>();
      const tinygltf::Value& binds = Member(group, "binds");
      for (size_t b = 0; binds.IsArray() && b < binds.ArrayLen(); ++b) {
        const tinygltf::Value& bind = Element(binds, b);
        const std::string bpart = kinemo::StrCat(part, ".binds[", b, "]");
        const double mesh = number(Member(bind, "mesh"), -1), index = number(Member(bind, "index"), -1);
        if (!(mesh >= 0 && mesh < 1e6 && index >= 0 && index < 1e6)) return InvalidField(bpart, "mesh or index out of range");
        KINEMO_RETURN_IF_ERROR(check(static_cast<int>(mesh), static_cast<int>(index), bpart));
        const double w = std::clamp(number(Member(bind, "weight"), 0) / 100.0, 0.0, 1.0);  // 0.x: percent
        x.binds.push_back({{static_cast<int>(mesh), static_cast<int>(index)}, static_cast<float>(w)});
      }
      x.other_binds = Member(group, "materialValues").IsArray() && Member(group, "materialValues").ArrayLen() > 0;
      out.push_back(std::move(x));
    }
  }
  return out;
}

// The names of a mesh's morph targets (mesh.extras.targetNames, or the first
// primitive's, as UniVRM writes them); "" where the file names none.
std::vector<std::string> TargetNames(const tinygltf::Mesh& mesh, int count) {
  std::vector<std::string> names(static_cast<size_t>(count));
  for (const tinygltf::Value* extras : {&mesh.extras, mesh.primitives.empty() ? nullptr : &mesh.primitives[0].extras}) {
    if (extras == nullptr) continue;
    const tinygltf::Value& list = Member(*extras, "targetNames");
    if (!list.IsArray()) continue;
    for (size_t i = 0; i < names.size() && i < list.ArrayLen(); ++i) {
      if (Element(list, i).IsString()) names[i] = Element(list, i).Get<std::string>();
    }
    return names;
  }
  return names;
}

// The rest position of joint j's "far end": the mean of its children, or its end site.
std::optional<Eigen::Vector3d> BoneDirection(const Rig& rig, int j) {
  const std::vector<Eigen::Vector3d> rest = rig.RestPositions();
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int n = 0;
  for (int c : rig.skeleton.children(j)) {
    sum += rest[static_cast<size_t>(c)];
    ++n;
  }
  Eigen::Vector3d d;
  if (n > 0) {
    d = sum / n - rest[static_cast<size_t>(j)];
  } else if (rig.skeleton.joint(j).end_site) {
    d = *rig.skeleton.joint(j).end_site;
  } else {
    return std::nullopt;
  }
  if (d.norm() < 1e-9) return std::nullopt;
  return d.normalized();
}

Status SetJaw(const Rig& rig, int joint, const std::string& found_by, JawBone* jaw) {
  jaw->joint = joint;
  jaw->name = rig.skeleton.joint(joint).name;
  jaw->found_by = found_by;
  Eigen::Vector3d left = rig.RestBodyAxes().upper.col(0);
  if (auto d = BoneDirection(rig, joint)) {
    const Eigen::Vector3d square = left - left.dot(*d) * *d;
    if (square.norm() > 0.1) left = square;
  }
  jaw->hinge_axis = left.normalized();
  if (rig.skeleton.joint(joint).num_rotations != 3) {
    return absl::InvalidArgumentError(kinemo::StrCat(rig.name, ": jaw joint ", jaw->name, " has no rotation channels"));
  }
  return absl::OkStatus();
}

// The jaw: the jaw role, else a joint named *jaw* below the head.
int FindJaw(const Rig& rig, std::string* found_by) {
  if (rig.roles.joint[roles::kJaw] >= 0) {
    *found_by = "role";
    return rig.roles.joint[roles::kJaw];
  }
  const int head = rig.roles.joint[roles::kHead];
  int best = -1;
  for (int j = 0; j < rig.skeleton.num_joints(); ++j) {
    const std::string name = face_names::Lower(rig.skeleton.joint(j).name);
    if (name.find("jaw") == std::string::npos || name.find("end") != std::string::npos ||
        name.find("tip") != std::string::npos) {
      continue;
    }
    bool under_head = head < 0;
    for (int a = rig.skeleton.joint(j).parent; a >= 0 && !under_head; a = rig.skeleton.joint(a).parent) under_head = a == head;
    if (!under_head) continue;
    if (best < 0 || rig.skeleton.depth(j) < rig.skeleton.depth(best)) best = j;
  }
  if (best >= 0) *found_by = "name";
  return best;
}

}  // namespace

std::string_view FaceInputName(int input) {
  return input >= 0 && input < kNumFaceInputs ? kInputNames[static_cast<size_t>(input)] : "";
}

std::optional<int> ParseFaceInput(std::string_view name) {
  for (int i = 0; i < kNumFaceInputs; ++i) {
    if (kInputNames[static_cast<size_t>(i)] == name) return i;
  }
  return std::nullopt;
}

void FaceInputs(const face::FaceFrame& frame, std::span<float, kNumFaceInputs> out, double jaw_full_open_deg,
                double vowel_open_deg) {
  auto unit = [](float v) { return std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f; };
  for (int v = 0; v < face::kNumOvrVisemes; ++v) out[static_cast<size_t>(v)] = unit(frame.ovr[static_cast<size_t>(v)]);
  if (frame.jaw_known && vowel_open_deg > 0) {
    const float open = unit(static_cast<float>(frame.jaw_open_deg / vowel_open_deg));
    for (face::OvrViseme v : kVowelVisemes) out[static_cast<size_t>(v)] *= open;
  }
  out[kInputJaw] = unit(static_cast<float>(frame.jaw_open_deg / std::max(jaw_full_open_deg, 1e-3)));
  out[kInputBlinkLeft] = unit(frame.blink_left);
  out[kInputBlinkRight] = unit(frame.blink_right);
  out[kInputBrowRaise] = unit(frame.brow_raise);
  const float w = unit(frame.expression_weight);
  out[kInputHappy] = frame.expression == face::Expression::kHappy ? w : 0;
  out[kInputAngry] = frame.expression == face::Expression::kAngry ? w : 0;
  out[kInputSad] = frame.expression == face::Expression::kSad ? w : 0;
  out[kInputSurprised] = frame.expression == face::Expression::kSurprised ? w : 0;
}

std::string FaceControl::DrivenBy(const std::vector<FaceControl>& all) const {
  if (follows >= 0 && follows < static_cast<int>(all.size())) return "follows " + all[static_cast<size_t>(follows)].name;
  if (terms.empty()) return why_not.empty() ? "not driven" : "not driven (" + why_not + ")";
  std::string out;
  for (const FaceTerm& t : terms) {
    out += kinemo::StrCat(out.empty() ? "" : " + ", FaceInputName(t.input), " ", face_names::FormatCoefficient(t.coefficient));
  }
  if (closes_for_pp) out += ", x(1-PP)";
  if (binary) out += ", binary";
  return out;
}

int FaceMap::num_driven() const {
  int n = 0;
  for (const FaceControl& c : controls_) n += c.driven() ? 1 : 0;
  return n;
}

StatusOr<FaceMap> FaceMap::Create(const Rig& rig, const FaceMapOptions& options) {
  FaceMap map;
  // The jaw (any rig with a skeleton).
  std::string found_by;
  if (const int jaw = FindJaw(rig, &found_by); jaw >= 0) KINEMO_RETURN_IF_ERROR(SetJaw(rig, jaw, found_by, &map.jaw_));

  // Morph targets and VRM expressions (glTF rigs).
  std::vector<int> targets_of_mesh;
  std::vector<VrmExpression> expressions;
  const tinygltf::Model* model = rig.gltf ? &rig.gltf->model : nullptr;
  if (model != nullptr) {
    for (const tinygltf::Mesh& mesh : model->meshes) {
      size_t count = 0;
      for (const tinygltf::Primitive& p : mesh.primitives) count = std::max(count, p.targets.size());
      targets_of_mesh.push_back(static_cast<int>(std::min<size_t>(count, 4096)));
    }
    auto read = ReadVrmExpressions(*model, targets_of_mesh);
    if (!read.ok()) return Annotate(read.status(), rig.name);
    expressions = *std::move(read);
  }
  const bool vrm1 = model != nullptr && model->extensions.count("VRMC_vrm") > 0;
  bool left_right_blinks = false;
  {
    int lr = 0;
    for (const VrmExpression& e : expressions) {
      lr += e.name == "blink_l" || e.name == "blinkLeft" || e.name == "blink_r" || e.name == "blinkRight";
    }
    left_right_blinks = lr >= 2;
  }
  struct Candidate {
    FaceControl control;
    std::string mouth_family;  // the family if its recipe is a mouth shape
  };
  std::vector<Candidate> cands;
  for (const VrmExpression& e : expressions) {
    Candidate c;
    c.control.kind = FaceControlKind::kVrmExpression;
    c.control.name = e.name;
    c.control.vmc_name = e.vmc_name;
    c.control.family = vrm1 ? "vrm1" : "vrm0";
    c.control.binary = e.binary;
    if (auto r = face_names::VrmRecipe(e.name, left_right_blinks)) {
      c.control.group = std::string(r->group);
      c.control.terms = r->terms;
      c.control.closes_for_pp = r->gate;
      if (r->group == "mouth") c.mouth_family = "vrm";
    } else {
      c.control.why_not = e.name == "blink" ? "blink_l / blink_r are driven" : "kinemo's face has no such channel";
    }
    cands.push_back(std::move(c));
  }
  // Morphs bound by a driven VRM expression.
  std::set<std::pair<int, int>> bound;
  for (size_t k = 0; k < expressions.size(); ++k) {
    if (!cands[k].control.terms.empty()) {
      for (const auto& b : expressions[k].binds) bound.insert(b.first);
    }
  }
  std::map<std::string, int> rocketbox_face;  // base name -> candidate (face morphs, for the teeth)
  std::vector<std::pair<int, std::string>> teeth;  // candidate -> base it follows
  if (model != nullptr) {
    for (size_t m = 0; m < model->meshes.size(); ++m) {
      const tinygltf::Mesh& mesh = model->meshes[m];
      const std::vector<std::string> names = TargetNames(mesh, targets_of_mesh[m]);
      for (int t = 0; t < targets_of_mesh[m]; ++t) {
        Candidate c;
        FaceControl& fc = c.control;
        fc.kind = FaceControlKind::kMorphTarget;
        fc.name = names[static_cast<size_t>(t)];
        fc.mesh = mesh.name.empty() ? kinemo::StrCat("mesh", m) : mesh.name;
        fc.mesh_index = static_cast<int>(m);
        fc.target = t;
        std::optional<face_names::Recipe> r;
        if (fc.name.empty()) {
          fc.why_not = "the file names no morph target here";
        } else if ((r = face_names::OvrRecipe(fc.name))) {
          fc.family = "ovr";
        } else if (face_names::IsRocketboxName(fc.name)) {
          fc.family = "rocketbox";
          const std::string base = face_names::RocketboxBase(fc.name);
          if (base.rfind("t_", 0) == 0) {
            fc.group = "teeth";
            teeth.emplace_back(static_cast<int>(cands.size()), base.substr(2));
          } else if ((r = face_names::RocketboxRecipe(base))) {
            rocketbox_face[base] = static_cast<int>(cands.size());
          } else {
            fc.why_not = "no recipe for this Rocketbox shape";
          }
        } else if ((r = face_names::ArkitRecipe(fc.name))) {
          fc.family = "arkit";
        } else if ((r = face_names::NamesRecipe(fc.name))) {
          fc.family = "names";
        } else {
          fc.why_not = "name not in a known family";
        }
        if (r) {
          fc.group = std::string(r->group);
          fc.terms = r->terms;
          fc.closes_for_pp = r->gate;
          if (r->group == "mouth" && !r->terms.empty()) c.mouth_family = fc.family;
          if (r->terms.empty()) fc.why_not = "kinemo's face has no such channel";
        }
        if (bound.count({static_cast<int>(m), t})) {
          fc.terms.clear();
          fc.closes_for_pp = false;
          c.mouth_family.clear();
          fc.why_not = "moved by a driven VRM expression";
        }
        cands.push_back(std::move(c));
      }
    }
  }
  // One mouth family: the richest the rig has.
  for (const char* family : {"ovr", "rocketbox", "arkit", "vrm", "names"}) {
    bool present = false;
    for (const Candidate& c : cands) present = present || c.mouth_family == family;
    if (present) {
      map.mouth_family_ = family == std::string("vrm") ? (vrm1 ? "vrm1" : "vrm0") : family;
      for (Candidate& c : cands) {
        if (!c.mouth_family.empty() && c.mouth_family != family) {
          c.control.terms.clear();
          c.control.closes_for_pp = false;
          c.control.why_not = kinemo::StrCat("the mouth is driven by the rig's ", map.mouth_family_, " shapes");
        }
      }
      break;
    }
  }
  // The mouth's opening morphs give way to a jaw bone.
  if (map.jaw_.joint >= 0) {
    for (Candidate& c : cands) {
      const bool jaw_only = c.control.terms.size() == 1 && c.control.terms[0].input == kInputJaw;
      if (jaw_only) {
        c.control.terms.clear();
        c.control.why_not = kinemo::StrCat("the jaw bone ", map.jaw_.name, " opens the mouth");
      }
    }
  }
  for (Candidate& c : cands) map.controls_.push_back(std::move(c.control));
  // Teeth follow the face morph of their name (t_MPB: MPB_Up).
  for (const auto& [k, base] : teeth) {
    FaceControl& fc = map.controls_[static_cast<size_t>(k)];
    auto it = rocketbox_face.find(base);
    if (it == rocketbox_face.end()) it = rocketbox_face.find(base + "_Up");
    if (it != rocketbox_face.end() && map.controls_[static_cast<size_t>(it->second)].driven()) {
      fc.follows = it->second;
    } else {
      fc.why_not = it == rocketbox_face.end() ? "no face morph of this name" : "its face morph is not driven";
    }
  }

  // The map file.
  if (!options.map_json.empty()) {
    const std::string& src = options.map_source;
    if (JsonNestingDepth(options.map_json, 16) > 16) return InvalidField(src, "nested too deep");
    const nlohmann::json j = nlohmann::json::parse(options.map_json, nullptr, false);
    if (j.is_discarded() || !j.is_object()) return InvalidField(src, "not a JSON object");
    for (auto it = j.begin(); it != j.end(); ++it) {
      static const std::set<std::string> kTop = {"automatic", "controls", "jaw_bone", "jaw_max_deg", "jaw_full_open_deg",
                                                 "vowel_open_deg"};
      if (!kTop.count(it.key())) {
        return InvalidField(kinemo::StrCat(src, ": ", it.key()),
                            "unknown key (automatic, controls, jaw_bone, jaw_max_deg, jaw_full_open_deg, vowel_open_deg)");
      }
    }
    bool automatic = true;
    if (auto a = j.find("automatic"); a != j.end()) {
      if (!a->is_boolean()) return InvalidField(kinemo::StrCat(src, ": automatic"), "must be true or false");
      automatic = a->get<bool>();
    }
    if (!automatic) {
      for (FaceControl& c : map.controls_) {
        c.terms.clear();
        c.follows = -1;
        c.closes_for_pp = false;
        c.why_not = "not in the map file";
      }
      map.jaw_ = JawBone();
      map.mouth_family_ = "map";
    }
    if (auto jb = j.find("jaw_bone"); jb != j.end()) {
      if (!jb->is_string()) return InvalidField(kinemo::StrCat(src, ": jaw_bone"), "must be a joint name (\"\" for none)");
      const std::string name = jb->get<std::string>();
      map.jaw_ = JawBone();
      if (!name.empty()) {
        const int joint = rig.skeleton.FindJoint(name);
        if (joint < 0) return InvalidField(kinemo::StrCat(src, ": jaw_bone"), "no joint '", name, "' in the rig");
        KINEMO_RETURN_IF_ERROR(SetJaw(rig, joint, "map", &map.jaw_));
      }
    }
    if (j.contains("jaw_max_deg")) {
      auto d = JsonNumber(j, "jaw_max_deg", std::nullopt, kinemo::StrCat(src, ": "));
      if (!d.ok()) return d.status();
      if (*d < 0 || *d > 90) return InvalidField(kinemo::StrCat(src, ": jaw_max_deg"), "must be in 0..90, got ", *d);
      map.jaw_.max_deg = *d;
    }
    if (j.contains("jaw_full_open_deg")) {
      auto d = JsonNumber(j, "jaw_full_open_deg", std::nullopt, kinemo::StrCat(src, ": "));
      if (!d.ok()) return d.status();
      if (*d < 0.5 || *d > 90) return InvalidField(kinemo::StrCat(src, ": jaw_full_open_deg"), "must be in 0.5..90, got ", *d);
      map.jaw_full_open_deg_ = *d;
    }
    if (j.contains("vowel_open_deg")) {
      auto d = JsonNumber(j, "vowel_open_deg", std::nullopt, kinemo::StrCat(src, ": "));
      if (!d.ok()) return d.status();
      if (!(*d == 0 || (*d >= 0.5 && *d <= 90))) {
        return InvalidField(kinemo::StrCat(src, ": vowel_open_deg"), "must be 0 (off) or in 0.5..90, got ", *d);
      }
      map.vowel_open_deg_ = *d;
    }
    if (auto cs = j.find("controls"); cs != j.end()) {
      if (!cs->is_array()) return InvalidField(kinemo::StrCat(src, ": controls"), "must be an array");
      if (cs->size() > 4096) return InvalidField(kinemo::StrCat(src, ": controls"), "more than 4096 entries");
      for (size_t k = 0; k < cs->size(); ++k) {
        const nlohmann::json& e = (*cs)[k];
        const std::string part = kinemo::StrCat(src, ": controls[", k, "]");
        if (!e.is_object()) return InvalidField(part, "must be an object");
        for (auto it = e.begin(); it != e.end(); ++it) {
          static const std::set<std::string> kKeys = {"morph", "mesh", "expression", "drive", "follow", "close_for_pp"};
          if (!kKeys.count(it.key())) return InvalidField(kinemo::StrCat(part, ".", it.key()), "unknown key (morph, mesh, expression, drive, follow, close_for_pp)");
        }
        const bool is_morph = e.contains("morph"), is_expr = e.contains("expression");
        if (is_morph == is_expr) return InvalidField(part, "needs exactly one of morph, expression");
        const nlohmann::json& nm = is_morph ? e["morph"] : e["expression"];
        if (!nm.is_string()) return InvalidField(kinemo::StrCat(part, is_morph ? ".morph" : ".expression"), "must be a name");
        std::string mesh;
        if (e.contains("mesh")) {
          if (!e["mesh"].is_string()) return InvalidField(part + ".mesh", "must be a mesh name");
          mesh = e["mesh"].get<std::string>();
        }
        std::vector<int> hits;
        for (size_t c = 0; c < map.controls_.size(); ++c) {
          const FaceControl& fc = map.controls_[c];
          if ((fc.kind == FaceControlKind::kMorphTarget) != is_morph || fc.name != nm.get<std::string>()) continue;
          if (!mesh.empty() && fc.mesh != mesh) continue;
          hits.push_back(static_cast<int>(c));
        }
        if (hits.empty()) {
          return InvalidField(kinemo::StrCat(part, is_morph ? ".morph" : ".expression"), "the rig has no ",
                              is_morph ? "morph target" : "VRM expression", " '", nm.get<std::string>(), "'",
                              mesh.empty() ? "" : kinemo::StrCat(" on mesh '", mesh, "'"));
        }
        std::vector<FaceTerm> terms;
        int follow = -1;
        if (e.contains("drive")) {
          const nlohmann::json& d = e["drive"];
          if (!d.is_object()) return InvalidField(part + ".drive", "must be an object {input: coefficient}");
          for (auto it = d.begin(); it != d.end(); ++it) {
            const auto input = ParseFaceInput(it.key());
            if (!input) {
              std::string all;
              for (auto n : kInputNames) all += kinemo::StrCat(all.empty() ? "" : " ", n);
              return InvalidField(kinemo::StrCat(part, ".drive.", it.key()), "not a face input (", all, ")");
            }
            if (!it->is_number() || !std::isfinite(it->get<double>()) || std::abs(it->get<double>()) > 10) {
              return InvalidField(kinemo::StrCat(part, ".drive.", it.key()), "must be a number in -10..10");
            }
            terms.push_back({*input, static_cast<float>(it->get<double>())});
          }
        } else if (e.contains("follow")) {
          if (!e["follow"].is_string()) return InvalidField(part + ".follow", "must be a morph target name");
          for (size_t c = 0; c < map.controls_.size() && follow < 0; ++c) {
            if (map.controls_[c].name == e["follow"].get<std::string>()) follow = static_cast<int>(c);
          }
          if (follow < 0) return InvalidField(part + ".follow", "the rig has no control '", e["follow"].get<std::string>(), "'");
          if (std::find(hits.begin(), hits.end(), follow) != hits.end()) return InvalidField(part + ".follow", "a control cannot follow itself");
        } else {
          return InvalidField(part, "needs drive or follow (\"drive\": {} leaves it undriven)");
        }
        bool gate = false;
        if (e.contains("close_for_pp")) {
          if (!e["close_for_pp"].is_boolean()) return InvalidField(part + ".close_for_pp", "must be true or false");
          gate = e["close_for_pp"].get<bool>();
        }
        for (int h : hits) {
          FaceControl& fc = map.controls_[static_cast<size_t>(h)];
          fc.terms = terms;
          fc.follows = follow;
          fc.closes_for_pp = gate;
          fc.family = "map";
          fc.why_not = terms.empty() && follow < 0 ? "the map file leaves it undriven" : "";
          if (fc.group.empty()) fc.group = "map";
        }
      }
    }
    // A follower of a follower, or of an undriven control, drives nothing.
    for (FaceControl& fc : map.controls_) {
      if (fc.follows >= 0 && !map.controls_[static_cast<size_t>(fc.follows)].terms.size()) {
        fc.follows = -1;
        fc.why_not = "what it follows is not driven";
      }
    }
  }

  // The meshes and binds the driven controls move.
  if (model != nullptr) {
    std::map<int, int> offset_of_mesh;
    auto flat = [&](int mesh, int target) {
      auto it = offset_of_mesh.find(mesh);
      if (it == offset_of_mesh.end()) {
        MorphMesh mm;
        mm.mesh = mesh;
        mm.name = model->meshes[static_cast<size_t>(mesh)].name.empty() ? kinemo::StrCat("mesh", mesh)
                                                                        : model->meshes[static_cast<size_t>(mesh)].name;
        mm.num_targets = targets_of_mesh[static_cast<size_t>(mesh)];
        mm.target_names = TargetNames(model->meshes[static_cast<size_t>(mesh)], mm.num_targets);
        for (size_t n = 0; n < model->nodes.size(); ++n) {
          if (model->nodes[n].mesh == mesh) mm.nodes.push_back(static_cast<int>(n));
        }
        it = offset_of_mesh.emplace(mesh, map.num_morph_weights_).first;
        map.num_morph_weights_ += mm.num_targets;
        map.morph_meshes_.push_back(std::move(mm));
      }
      return it->second + target;
    };
    for (size_t c = 0; c < map.controls_.size(); ++c) {
      const FaceControl& fc = map.controls_[c];
      if (!fc.driven()) continue;
      if (fc.kind == FaceControlKind::kMorphTarget) {
        map.binds_.push_back({static_cast<int>(c), flat(fc.mesh_index, fc.target), 1.0f});
      } else {
        for (const VrmExpression& e : expressions) {
          if (e.name != fc.name) continue;
          for (const auto& [mt, w] : e.binds) map.binds_.push_back({static_cast<int>(c), flat(mt.first, mt.second), w});
        }
      }
    }
    // Morph meshes drawn by no node are not animated (nothing to target).
  }
  return map;
}

float ControlWeight(const FaceControl& fc, std::span<const float, kNumFaceInputs> in) {
  float w = 0;
  for (const FaceTerm& t : fc.terms) w += t.coefficient * in[static_cast<size_t>(t.input)];
  w = std::clamp(w, 0.0f, 1.0f);
  if (fc.closes_for_pp) w *= 1.0f - in[face_names::kPP];
  if (fc.binary) w = w > 0.5f ? 1.0f : 0.0f;
  return w;
}

std::optional<FaceControl> VrmPresetControl(std::string_view name, bool per_eye_blinks) {
  const std::optional<face_names::Recipe> r = face_names::VrmRecipe(std::string(name), per_eye_blinks);
  if (!r) return std::nullopt;
  FaceControl c;
  c.kind = FaceControlKind::kVrmExpression;
  c.name = std::string(name);
  c.group = std::string(r->group);
  c.terms = r->terms;
  c.closes_for_pp = r->gate;
  return c;
}

void FaceMap::Weights(const face::FaceFrame& frame, std::span<float> weights) const {
  std::array<float, kNumFaceInputs> in;
  FaceInputs(frame, in, jaw_full_open_deg_, vowel_open_deg_);
  const size_t n = std::min(weights.size(), controls_.size());
  for (size_t c = 0; c < n; ++c) weights[c] = ControlWeight(controls_[c], in);
  for (size_t c = 0; c < n; ++c) {
    const int f = controls_[c].follows;
    if (f >= 0 && static_cast<size_t>(f) < n) weights[c] = weights[static_cast<size_t>(f)];
  }
}

double FaceMap::JawAngleDeg(const face::FaceFrame& frame) const {
  if (jaw_.joint < 0 || !std::isfinite(frame.jaw_open_deg)) return 0;
  const float raw = frame.ovr[static_cast<size_t>(face_names::kPP)];
  const float pp = std::isfinite(raw) ? std::clamp(raw, 0.0f, 1.0f) : 0.0f;
  return std::clamp(static_cast<double>(frame.jaw_open_deg) * (1.0 - pp), 0.0, jaw_.max_deg);
}

Status FaceMap::ApplyJaw(const motion::Skeleton& skeleton, double angle_deg, std::span<double> frame) const {
  if (jaw_.joint < 0) return absl::OkStatus();
  if (jaw_.joint >= skeleton.num_joints() || frame.size() != static_cast<size_t>(skeleton.num_channels())) {
    return absl::InvalidArgumentError("FaceMap::ApplyJaw: the frame is not on the rig's skeleton");
  }
  const motion::Joint& joint = skeleton.joint(jaw_.joint);
  if (joint.num_rotations != 3) return absl::OkStatus();
  const Eigen::Matrix3d r = Eigen::AngleAxisd(angle_deg * M_PI / 180.0, jaw_.hinge_axis).toRotationMatrix();
  Eigen::Vector3d reference;
  for (int k = 0; k < 3; ++k) reference[k] = frame[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(k)])];
  const Eigen::Vector3d angles = motion::MatrixToEuler(r, joint.rotation_axis, reference);
  for (int k = 0; k < 3; ++k) frame[static_cast<size_t>(joint.rotation_column[static_cast<size_t>(k)])] = angles[k];
  return absl::OkStatus();
}

void FaceMap::MorphWeights(std::span<const float> control_weights, std::span<float> morph_weights) const {
  std::fill(morph_weights.begin(), morph_weights.end(), 0.0f);
  for (const Bind& b : binds_) {
    if (static_cast<size_t>(b.control) < control_weights.size() && static_cast<size_t>(b.flat) < morph_weights.size()) {
      morph_weights[static_cast<size_t>(b.flat)] += b.weight * control_weights[static_cast<size_t>(b.control)];
    }
  }
  for (float& w : morph_weights) w = std::clamp(w, 0.0f, 1.0f);
}

StatusOr<FaceAnimation> SampleFace(const FaceMap& map, const face::FaceTrack& track, int num_frames,
                                   double frame_time_s) {
  if (!(track.frame_time_s > 0 && track.frame_time_s <= 1)) {
    return InvalidField("face.frame_time_s", "must be in (0, 1] s, got ", track.frame_time_s);
  }
  if (track.frames.empty()) return InvalidField("face.frames", "no frames");
  if (track.frames.size() > 10'000'000) return InvalidField("face.frames", "more than 10^7 frames");
  if (num_frames < 0 || !(frame_time_s > 0)) return absl::InvalidArgumentError("SampleFace: bad clip timing");
  const size_t nc = map.controls().size();
  const size_t nm = static_cast<size_t>(map.num_morph_weights());
  std::vector<float> per_face(track.frames.size() * nc);
  std::vector<double> jaw_face(track.frames.size());
  for (size_t i = 0; i < track.frames.size(); ++i) {
    map.Weights(track.frames[i], std::span<float>(per_face).subspan(i * nc, nc));
    jaw_face[i] = map.JawAngleDeg(track.frames[i]);
  }
  FaceAnimation out;
  out.num_frames = num_frames;
  out.control_weights.resize(static_cast<size_t>(num_frames) * nc);
  out.morph_weights.resize(static_cast<size_t>(num_frames) * nm);
  out.jaw_deg.resize(static_cast<size_t>(num_frames));
  const size_t last = track.frames.size() - 1;
  for (int f = 0; f < num_frames; ++f) {
    const double x = f * frame_time_s / track.frame_time_s;
    const size_t i = x <= 0 ? 0 : std::min(static_cast<size_t>(x), last);
    const size_t k = std::min(i + 1, last);
    const float a = static_cast<float>(std::clamp(x - static_cast<double>(i), 0.0, 1.0));
    float* cw = out.control_weights.data() + static_cast<size_t>(f) * nc;
    for (size_t c = 0; c < nc; ++c) cw[c] = (1 - a) * per_face[i * nc + c] + a * per_face[k * nc + c];
    map.MorphWeights(std::span<const float>(cw, nc),
                     std::span<float>(out.morph_weights.data() + static_cast<size_t>(f) * nm, nm));
    out.jaw_deg[static_cast<size_t>(f)] = (1 - a) * jaw_face[i] + a * jaw_face[k];
  }
  return out;
}

Status ApplyJawToClip(const FaceMap& map, const FaceAnimation& face, motion::Clip* clip) {
  if (map.jaw().joint < 0) return absl::OkStatus();
  if (face.num_frames != clip->num_frames()) return absl::InvalidArgumentError("ApplyJawToClip: frame counts differ");
  const Eigen::Index cols = clip->frames.cols();
  for (int f = 0; f < clip->num_frames(); ++f) {
    std::span<double> row(clip->frames.data() + static_cast<Eigen::Index>(f) * cols, static_cast<size_t>(cols));
    KINEMO_RETURN_IF_ERROR(map.ApplyJaw(clip->skeleton, face.jaw_deg[static_cast<size_t>(f)], row));
  }
  return absl::OkStatus();
}

}  // namespace kinemo::retarget
