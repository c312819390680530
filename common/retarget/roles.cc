#include "common/retarget/roles.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <unordered_map>

namespace kinemo::retarget {
namespace {

constexpr std::array<std::string_view, kNumCoreRoles> kCoreNames = {"hips", "spine", "chest", "upper_chest",
                                                                  "neck", "head",  "jaw"};
constexpr std::array<std::string_view, 8> kLimbNames = {"shoulder", "upper_arm", "forearm", "hand",
                                                        "thigh",    "shin",      "foot",    "toes"};
constexpr std::array<std::string_view, 5> kFingerNames = {"thumb", "index", "middle", "ring", "little"};

const std::array<std::string, kNumRoles>& RoleNameTable() {
  static const auto* table = [] {
    auto* t = new std::array<std::string, kNumRoles>;
    for (int r = 0; r < kNumCoreRoles; ++r) (*t)[r] = std::string(kCoreNames[r]);
    for (int side = 0; side < 2; ++side) {
      const std::string prefix = side == 0 ? "left_" : "right_";
      for (int b = 0; b < 8; ++b) (*t)[roles::Side(side, b)] = prefix + std::string(kLimbNames[b]);
      for (int f = 0; f < 5; ++f) {
        for (int b = 0; b < 3; ++b) {
          (*t)[roles::Finger(side, f, b)] = prefix + std::string(kFingerNames[f]) + std::to_string(b + 1);
        }
      }
    }
    return t;
  }();
  return *table;
}

// Role names from a family's spelling: core names, a limb pattern per bone
// and a finger pattern, where "{s}" is replaced by the side token and, in the
// finger pattern, "{f}" by the finger's name and "{n}" by the bone number
// plus `finger_base`.
struct FamilySpelling {
  RigFamily family;
  std::array<const char*, kNumCoreRoles> core;
  std::array<const char*, 2> side_token;
  std::array<const char*, 8> limb;
  const char* finger_pattern;  // nullptr: no fingers
  std::array<const char*, 5> finger;
  int finger_base = 1;
  int thumb_base = 1;
};

std::string Substitute(std::string_view pattern, std::string_view s, std::string_view f, int n) {
  std::string out;
  for (size_t i = 0; i < pattern.size(); ++i) {
    if (pattern.substr(i, 3) == "{s}") {
      out += s;
      i += 2;
    } else if (pattern.substr(i, 3) == "{f}") {
      out += f;
      i += 2;
    } else if (pattern.substr(i, 3) == "{n}") {
      out += std::to_string(n);
      i += 2;
    } else {
      out += pattern[i];
    }
  }
  return out;
}

RoleNames Spell(const FamilySpelling& sp) {
  RoleNames names{sp.family, {}};
  for (int r = 0; r < kNumCoreRoles; ++r) names.names[r] = sp.core[r];
  for (int side = 0; side < 2; ++side) {
    for (int b = 0; b < 8; ++b) {
      if (*sp.limb[b]) names.names[roles::Side(side, b)] = Substitute(sp.limb[b], sp.side_token[side], "", 0);
    }
    if (sp.finger_pattern == nullptr) continue;
    for (int f = 0; f < 5; ++f) {
      const int base = f == 0 ? sp.thumb_base : sp.finger_base;
      for (int b = 0; b < 3; ++b) {
        names.names[roles::Finger(side, f, b)] = Substitute(sp.finger_pattern, sp.side_token[side], sp.finger[f], base + b);
      }
    }
  }
  return names;
}

const std::vector<RoleNames>& BuiltIns() {
  static const auto* tables = [] {
    auto* t = new std::vector<RoleNames>;
    // SMPL-X (BEAT2 export): left_shoulder is the upper arm, left_foot the toes.
    t->push_back(Spell({RigFamily::kSmplx,
                        {"pelvis", "spine1", "spine2", "spine3", "neck", "head", "jaw"},
                        {"left", "right"},
                        {"{s}_collar", "{s}_shoulder", "{s}_elbow", "{s}_wrist", "{s}_hip", "{s}_knee",
                         "{s}_ankle", "{s}_foot"},
                        "{s}_{f}{n}",
                        {"thumb", "index", "middle", "ring", "pinky"}}));
    // Bandai-Namco motion dataset: no fingers.
    t->push_back(Spell({RigFamily::kBandai,
                        {"Hips", "Spine", "Chest", "", "Neck", "Head", ""},
                        {"L", "R"},
                        {"Shoulder_{s}", "UpperArm_{s}", "LowerArm_{s}", "Hand_{s}", "UpperLeg_{s}",
                         "LowerLeg_{s}", "Foot_{s}", "Toes_{s}"},
                        nullptr,
                        {}}));
    // CMU, cgspeed's BVH conversion: LeftShoulder is the humerus, LeftWrist
    // the joint that turns the hand; the finger stubs are not mapped.
    t->push_back(Spell({RigFamily::kCmu31,
                        {"Hips", "lowerback", "Chest", "Chest2", "lowerneck", "Head", ""},
                        {"Left", "Right"},
                        {"{s}Collar", "{s}Shoulder", "{s}Elbow", "{s}Wrist", "{s}Hip", "{s}Knee", "{s}Ankle",
                         "{s}Toe"},
                        nullptr,
                        {}}));
    // CMU retargeted to iClone / Character Creator.
    t->push_back(Spell({RigFamily::kCmuIclone,
                        {"CC_Base_Hip", "CC_Base_Waist", "CC_Base_Spine01", "CC_Base_Spine02", "CC_Base_NeckTwist01",
                         "CC_Base_Head", "CC_Base_JawRoot"},
                        {"L", "R"},
                        {"CC_Base_{s}_Clavicle", "CC_Base_{s}_Upperarm", "CC_Base_{s}_Forearm", "CC_Base_{s}_Hand",
                         "CC_Base_{s}_Thigh", "CC_Base_{s}_Calf", "CC_Base_{s}_Foot", "CC_Base_{s}_ToeBase"},
                        "CC_Base_{s}_{f}{n}",
                        {"Thumb", "Index", "Mid", "Ring", "Pinky"}}));
    // Mixamo (names after the "mixamorig:" prefix, which DetectRoleMap strips).
    t->push_back(Spell({RigFamily::kMixamo,
                        {"Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", ""},
                        {"Left", "Right"},
                        {"{s}Shoulder", "{s}Arm", "{s}ForeArm", "{s}Hand", "{s}UpLeg", "{s}Leg", "{s}Foot",
                         "{s}ToeBase"},
                        "{s}Hand{f}{n}",
                        {"Thumb", "Index", "Middle", "Ring", "Pinky"}}));
    // Quaternius characters: Index2..4 are the phalanges (1 would be the
    // metacarpal), the thumb has Thumb2 (proximal) and Thumb3.
    t->push_back(Spell({RigFamily::kQuaternius,
                        {"Hips", "Abdomen", "Torso", "Chest", "Neck", "Head", ""},
                        {"L", "R"},
                        {"Shoulder.{s}", "UpperArm.{s}", "LowerArm.{s}", "Hand.{s}", "UpperLeg.{s}", "LowerLeg.{s}",
                         "Foot.{s}", "Toes.{s}"},
                        "{f}{n}.{s}",
                        {"Thumb", "Index", "Middle", "Ring", "Pinky"},
                        /*finger_base=*/2,
                        /*thumb_base=*/1}));
    return t;
  }();
  return *tables;
}

std::string_view AfterColon(std::string_view name) {
  const size_t colon = name.rfind(':');
  return colon == std::string_view::npos ? name : name.substr(colon + 1);
}

}  // namespace

std::string_view RoleName(Role role) {
  if (role < 0 || role >= kNumRoles) return "none";
  return RoleNameTable()[role];
}

std::optional<Role> ParseRole(std::string_view name) {
  const auto& t = RoleNameTable();
  for (int r = 0; r < kNumRoles; ++r) {
    if (t[r] == name) return r;
  }
  return std::nullopt;
}

bool IsFingerRole(Role role) {
  if (role < kNumCoreRoles || role >= kNumRoles) return false;
  return (role - kNumCoreRoles) % kNumSideRoles >= roles::kFirstFinger;
}

Role ChildRole(Role role) {
  using namespace roles;
  if (role < 0 || role >= kNumRoles) return -1;
  if (role < kNumCoreRoles) {
    switch (role) {
      case kHips: return kSpine;
      case kSpine: return kChest;
      case kChest: return kUpperChest;
      case kUpperChest: return kNeck;
      case kNeck: return kHead;
      default: return -1;
    }
  }
  const int side = (role - kNumCoreRoles) / kNumSideRoles;
  const int bone = (role - kNumCoreRoles) % kNumSideRoles;
  if (bone >= kFirstFinger) {
    const int b = (bone - kFirstFinger) % 3;
    return b < 2 ? role + 1 : -1;
  }
  switch (bone) {
    case kShoulder: return Side(side, kUpperArm);
    case kUpperArm: return Side(side, kForearm);
    case kForearm: return Side(side, kHand);
    case kHand: return Finger(side, 2, 0);  // middle1
    case kThigh: return Side(side, kShin);
    case kShin: return Side(side, kFoot);
    case kFoot: return Side(side, kToes);
    default: return -1;
  }
}

Role ParentRole(Role role) {
  using namespace roles;
  if (role <= kHips || role >= kNumRoles) return -1;
  if (role < kNumCoreRoles) return role == kJaw ? kHead : role - 1;
  const int side = (role - kNumCoreRoles) / kNumSideRoles;
  const int bone = (role - kNumCoreRoles) % kNumSideRoles;
  if (bone >= kFirstFinger) return (bone - kFirstFinger) % 3 == 0 ? Side(side, kHand) : role - 1;
  switch (bone) {
    case kShoulder: return kUpperChest;
    case kThigh: return kHips;
    default: return role - 1;
  }
}

std::vector<std::string> MissingRequiredRoles(const std::array<int, kNumRoles>& joints) {
  using namespace roles;
  std::vector<std::string> missing;
  auto need = [&](Role r) {
    if (joints[r] < 0) missing.emplace_back(RoleName(r));
  };
  need(kHips);
  if (joints[kSpine] < 0 && joints[kChest] < 0 && joints[kUpperChest] < 0) missing.emplace_back("spine|chest");
  need(kHead);
  for (int side = 0; side < 2; ++side) {
    for (int b : {kUpperArm, kForearm, kThigh, kShin}) need(Side(side, b));
  }
  return missing;
}

std::string_view RigFamilyName(RigFamily family) {
  switch (family) {
    case RigFamily::kCustom: return "custom";
    case RigFamily::kSmplx: return "smplx";
    case RigFamily::kBandai: return "bandai";
    case RigFamily::kCmu31: return "cmu31";
    case RigFamily::kCmuIclone: return "cmu_iclone";
    case RigFamily::kMixamo: return "mixamo";
    case RigFamily::kVrm: return "vrm";
    case RigFamily::kQuaternius: return "quaternius";
  }
  return "custom";
}

int RoleMap::num_mapped() const {
  return static_cast<int>(std::count_if(joint.begin(), joint.end(), [](int j) { return j >= 0; }));
}

std::span<const RoleNames> BuiltInRoleNames() { return BuiltIns(); }

StatusOr<RoleMap> DetectRoleMap(std::span<const std::string> joint_names) {
  // Names as written and without a namespace prefix ("mixamorig:Hips").
  std::unordered_map<std::string_view, int> exact, stripped;
  for (int i = 0; i < static_cast<int>(joint_names.size()); ++i) {
    exact.emplace(joint_names[i], i);
    stripped.emplace(AfterColon(joint_names[i]), i);
  }
  auto find = [&](const std::string& name) {
    if (auto it = exact.find(name); it != exact.end()) return it->second;
    if (auto it = stripped.find(name); it != stripped.end()) return it->second;
    return -1;
  };
  std::optional<RoleMap> best;
  size_t best_missing = 0;
  for (const RoleNames& names : BuiltIns()) {
    RoleMap map = ResolveRoleNames(names, find);
    const size_t missing = MissingRequiredRoles(map.joint).size();
    if (!best || missing < best_missing || (missing == best_missing && map.num_mapped() > best->num_mapped())) {
      best = map;
      best_missing = missing;
    }
  }
  if (best_missing > 0) {
    std::string list;
    for (const std::string& r : MissingRequiredRoles(best->joint)) list += (list.empty() ? "" : ", ") + r;
    return absl::NotFoundError(kinemo::StrCat(
        "no built-in bone map fits this skeleton (closest: ", RigFamilyName(best->family), ", missing roles: ", list,
        "); give a JSON map {\"role\": \"joint name\"} with --map"));
  }
  return *best;
}

StatusOr<RoleNames> ParseRoleMapJson(std::string_view text, std::string_view source_name) {
  nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) {
    return absl::InvalidArgumentError(kinemo::StrCat(source_name, ": not a JSON object {\"role\": \"joint name\"}"));
  }
  RoleNames names{RigFamily::kCustom, {}};
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::optional<Role> role = ParseRole(it.key());
    if (!role) {
      return InvalidField(kinemo::StrCat(source_name, ": ", it.key()), "not a role (roles: hips, spine, chest, ",
                          "upper_chest, neck, head, jaw, left_/right_ shoulder, upper_arm, forearm, hand, thigh, ",
                          "shin, foot, toes, thumb1..3, index1..3, middle1..3, ring1..3, little1..3)");
    }
    if (!it.value().is_string() || it.value().get<std::string>().empty() ||
        it.value().get<std::string>().size() > 256) {
      return InvalidField(kinemo::StrCat(source_name, ": ", it.key()), "must be a joint name (1..256 characters)");
    }
    names.names[*role] = it.value().get<std::string>();
  }
  return names;
}

StatusOr<RoleMap> ApplyRoleNames(const RoleNames& names, std::span<const std::string> joint_names,
                                 std::string_view source_name) {
  RoleMap map;
  map.family = names.family;
  for (int r = 0; r < kNumRoles; ++r) {
    if (names.names[r].empty()) continue;
    const auto it = std::find(joint_names.begin(), joint_names.end(), names.names[r]);
    if (it == joint_names.end()) {
      return InvalidField(kinemo::StrCat(source_name, ": ", RoleName(r)), "joint '", names.names[r],
                          "' is not in the skeleton");
    }
    map.joint[r] = static_cast<int>(it - joint_names.begin());
  }
  return map;
}

}  // namespace kinemo::retarget
