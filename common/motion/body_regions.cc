#include "common/motion/body_regions.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <utility>

#include "common/motion/text_util.h"

namespace kinemo::motion {
namespace {

constexpr std::string_view kRegionNames[kNumBodyRegions] = {
    "head", "trunk", "left_arm", "right_arm", "left_hand", "right_hand", "left_leg", "right_leg"};

// Built-in rules, in the same text format as rule files.
constexpr std::string_view kBandai22Rules = R"(# Bandai-Namco Research Motion dataset-1 (22 joints)
joint_Root  trunk
Hips        trunk
Spine       trunk
Chest       trunk
Neck        head
Head        head
Shoulder_L  left_arm
UpperArm_L  left_arm
LowerArm_L  left_arm
Hand_L      left_hand
Shoulder_R  right_arm
UpperArm_R  right_arm
LowerArm_R  right_arm
Hand_R      right_hand
UpperLeg_L  left_leg
LowerLeg_L  left_leg
Foot_L      left_leg
Toes_L      left_leg
UpperLeg_R  right_leg
LowerLeg_R  right_leg
Foot_R      right_leg
Toes_R      right_leg
)";

constexpr std::string_view kCmuIcloneRules =
    R"(# CMU mocap retargeted to iClone / Character Creator (CC_Base_*, 100 joints)
RL_BoneRoot            trunk
CC_Base_Hip            trunk
CC_Base_Pelvis         trunk
CC_Base_Waist          trunk
CC_Base_Spine??        trunk
CC_Base_?_RibsTwist    trunk
CC_Base_?_Breast       trunk
CC_Base_NeckTwist??    head
CC_Base_Head           head
CC_Base_FacialBone     head
CC_Base_JawRoot        head
CC_Base_UpperJaw       head
CC_Base_Tongue??       head
CC_Base_Teeth??        head
CC_Base_?_Eye          head
CC_Base_L_Clavicle     left_arm
CC_Base_L_Upperarm*    left_arm
CC_Base_L_Forearm*     left_arm
CC_Base_L_ElbowShareBone left_arm
CC_Base_L_Hand         left_hand
CC_Base_L_Thumb?       left_hand
CC_Base_L_Index?       left_hand
CC_Base_L_Mid?         left_hand
CC_Base_L_Ring?        left_hand
CC_Base_L_Pinky?       left_hand
CC_Base_R_Clavicle     right_arm
CC_Base_R_Upperarm*    right_arm
CC_Base_R_Forearm*     right_arm
CC_Base_R_ElbowShareBone right_arm
CC_Base_R_Hand         right_hand
CC_Base_R_Thumb?       right_hand
CC_Base_R_Index?       right_hand
CC_Base_R_Mid?         right_hand
CC_Base_R_Ring?        right_hand
CC_Base_R_Pinky?       right_hand
CC_Base_L_Thigh*       left_leg
CC_Base_L_Calf*        left_leg
CC_Base_L_KneeShareBone left_leg
CC_Base_L_Foot         left_leg
CC_Base_L_ToeBase*     left_leg
CC_Base_L_*Toe1        left_leg
CC_Base_R_Thigh*       right_leg
CC_Base_R_Calf*        right_leg
CC_Base_R_KneeShareBone right_leg
CC_Base_R_Foot         right_leg
CC_Base_R_ToeBase*     right_leg
CC_Base_R_*Toe1        right_leg
)";

constexpr std::string_view kCmu31Rules = R"(# CMU mocap, cgspeed BVH conversion (31 joints)
Hips          trunk
lowerback     trunk
Chest         trunk
Chest2        trunk
lowerneck     head
Neck          head
Head          head
LHipJoint     left_leg
LeftHip       left_leg
LeftKnee      left_leg
LeftAnkle     left_leg
LeftToe       left_leg
RHipJoint     right_leg
RightHip      right_leg
RightKnee     right_leg
RightAnkle    right_leg
RightToe      right_leg
LeftCollar    left_arm
LeftShoulder  left_arm
LeftElbow     left_arm
LeftWrist     left_hand
lhand         left_hand
LFingers      left_hand
LThumb        left_hand
RightCollar   right_arm
RightShoulder right_arm
RightElbow    right_arm
RightWrist    right_hand
rhand         right_hand
RFingers      right_hand
RThumb        right_hand
)";

constexpr std::string_view kSmplx55Rules = R"(# SMPL-X joint tree (55 joints: body, jaw, eyes, 15 finger joints per hand),
# as BEAT2 and other SMPL-X exports write it. Note: left_foot/right_foot are
# the balls of the feet (toe joints); the ankles are left_ankle/right_ankle.
pelvis            trunk
spine?            trunk
neck              head
head              head
jaw               head
?*_eye_smplhf     head
left_collar       left_arm
left_shoulder     left_arm
left_elbow        left_arm
left_wrist        left_hand
left_index?       left_hand
left_middle?      left_hand
left_ring?        left_hand
left_pinky?       left_hand
left_thumb?       left_hand
right_collar      right_arm
right_shoulder    right_arm
right_elbow       right_arm
right_wrist       right_hand
right_index?      right_hand
right_middle?     right_hand
right_ring?       right_hand
right_pinky?      right_hand
right_thumb?      right_hand
left_hip          left_leg
left_knee         left_leg
left_ankle        left_leg
left_foot         left_leg
right_hip         right_leg
right_knee        right_leg
right_ankle       right_leg
right_foot        right_leg
)";

BodyRegionRules MustParse(std::string_view text, std::string_view name) {
  StatusOr<BodyRegionRules> rules = BodyRegionRules::Parse(text, name);
  if (!rules.ok()) {
    // Built-in tables are tested; this cannot happen at run time.
    std::fprintf(stderr, "kinemo_motion: bad built-in rules %s: %s\n", std::string(name).c_str(),
                 std::string(rules.status().message()).c_str());
    std::abort();
  }
  return *std::move(rules);
}

// Splits a joint name into lowercase words at non-alphanumerics and at
// lower→upper case changes ("CC_Base_L_Hand" → cc base l hand).
std::vector<std::string> Words(std::string_view name) {
  std::vector<std::string> words;
  std::string cur;
  for (size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    if (!std::isalnum(static_cast<unsigned char>(c))) {
      if (!cur.empty()) words.push_back(std::move(cur));
      cur.clear();
      continue;
    }
    if (std::isupper(static_cast<unsigned char>(c)) && i > 0 &&
        std::islower(static_cast<unsigned char>(name[i - 1])) && !cur.empty()) {
      words.push_back(std::move(cur));
      cur.clear();
    }
    cur.push_back(internal::AsciiLower(c));
  }
  if (!cur.empty()) words.push_back(std::move(cur));
  return words;
}

template <typename Range>
bool ContainsAny(std::string_view s, const Range& words) {
  for (std::string_view w : words) {
    if (internal::Contains(s, w)) return true;
  }
  return false;
}

constexpr std::string_view kLegWords[] = {"toe", "foot",  "ankle", "knee",
                                          "leg", "thigh", "calf",  "shin"};
constexpr std::string_view kHandWords[] = {"hand",   "wrist", "finger", "thumb", "index",
                                           "middle", "mid",   "ring",   "pinky", "palm"};
constexpr std::string_view kArmWords[] = {"shoulder", "arm", "elbow", "clavicle", "collar"};
constexpr std::string_view kHeadWords[] = {"head",   "neck",  "eye",  "jaw",  "face", "facial",
                                           "tongue", "teeth", "nose", "brow", "lip"};
constexpr std::string_view kTrunkWords[] = {"spine",   "chest", "pelvis", "waist",  "back", "torso",
                                            "abdomen", "root",  "hip",    "breast", "rib"};

constexpr std::string_view kSidePrefixWords[] = {
    "toe",      "foot", "ankle", "knee",     "leg",    "thigh", "calf",
    "shin",     "hip",  "hand",  "wrist",    "finger", "thumb", "index",
    "shoulder", "arm",  "elbow", "clavicle", "collar", "up",    "fore"};

// Guesses a region from the words of a joint name; nullopt when unsure.
std::optional<BodyRegion> GuessRegion(std::string_view name) {
  const std::string lower = internal::ToLower(name);
  int side = 0;  // 1 left, 2 right
  if (internal::Contains(lower, "left")) {
    side = 1;
  } else if (internal::Contains(lower, "right")) {
    side = 2;
  } else {
    for (const std::string& w : Words(name)) {
      if (w == "l") side = 1;
      if (w == "r") side = 2;
    }
    // "LHipJoint", "lhand", "RThumb": a one-letter side prefix on a body word.
    if (side == 0 && lower.size() > 1 && (lower[0] == 'l' || lower[0] == 'r')) {
      const std::string_view rest = std::string_view(lower).substr(1);
      const bool body_word =
          std::any_of(std::begin(kSidePrefixWords), std::end(kSidePrefixWords),
                      [rest](std::string_view w) { return rest.starts_with(w); });
      if (body_word) side = lower[0] == 'l' ? 1 : 2;
    }
  }
  const auto sided = [side](BodyRegion left, BodyRegion right) -> std::optional<BodyRegion> {
    if (side == 0) return std::nullopt;
    return side == 1 ? left : right;
  };
  if (ContainsAny(lower, kLegWords)) return sided(BodyRegion::kLeftLeg, BodyRegion::kRightLeg);
  if (internal::Contains(lower, "hip") && side != 0) {
    return sided(BodyRegion::kLeftLeg, BodyRegion::kRightLeg);
  }
  if (ContainsAny(lower, kHandWords)) return sided(BodyRegion::kLeftHand, BodyRegion::kRightHand);
  if (ContainsAny(lower, kArmWords)) return sided(BodyRegion::kLeftArm, BodyRegion::kRightArm);
  if (ContainsAny(lower, kHeadWords)) return BodyRegion::kHead;
  if (ContainsAny(lower, kTrunkWords)) return BodyRegion::kTrunk;
  return std::nullopt;
}

template <typename Range>
std::string Join(const Range& parts, std::string_view sep) {
  std::string out;
  for (std::string_view p : parts) {
    if (!out.empty()) out += sep;
    out += p;
  }
  return out;
}

bool IsInRegion(const BodyRegionMap& map, int j, BodyRegion r) {
  return map.region[static_cast<size_t>(j)] == r;
}

// Topmost joint of a region (its parent is outside the region); the
// shallowest one if several.
int TopmostIn(const Skeleton& sk, const BodyRegionMap& map, BodyRegion r) {
  int best = -1;
  for (int j = 0; j < sk.num_joints(); ++j) {
    if (!IsInRegion(map, j, r)) continue;
    const int p = sk.joint(j).parent;
    if (p >= 0 && IsInRegion(map, p, r)) continue;
    if (best < 0 || sk.depth(j) < sk.depth(best)) best = j;
  }
  return best;
}

// Shallowest joint in region r (and in the subtree of `under`, if ≥ 0)
// whose lowercase name contains one of `words`.
int ShallowestNamed(const Skeleton& sk, const BodyRegionMap& map, BodyRegion r, int under,
                    std::initializer_list<std::string_view> words) {
  int best = -1;
  for (int j = 0; j < sk.num_joints(); ++j) {
    if (!IsInRegion(map, j, r) || j == under) continue;
    if (under >= 0) {
      int p = sk.joint(j).parent;
      while (p >= 0 && p != under) p = sk.joint(p).parent;
      if (p != under) continue;
    }
    if (!ContainsAny(internal::ToLower(sk.joint(j).name), words)) continue;
    if (best < 0 || sk.depth(j) < sk.depth(best)) best = j;
  }
  return best;
}

}  // namespace

std::string_view BodyRegionName(BodyRegion region) {
  return kRegionNames[static_cast<int>(region)];
}

std::optional<BodyRegion> ParseBodyRegion(std::string_view name) {
  for (int i = 0; i < kNumBodyRegions; ++i) {
    if (internal::EqualsIgnoreCase(name, kRegionNames[i])) return static_cast<BodyRegion>(i);
  }
  return std::nullopt;
}

std::string_view SkeletonFamilyName(SkeletonFamily family) {
  switch (family) {
    case SkeletonFamily::kBandai22:
      return "bandai22";
    case SkeletonFamily::kCmuIclone100:
      return "cmu_iclone100";
    case SkeletonFamily::kCmu31:
      return "cmu31";
    case SkeletonFamily::kSmplx55:
      return "smplx55";
    case SkeletonFamily::kUnknown:
      break;
  }
  return "unknown";
}

SkeletonFamily DetectSkeletonFamily(const Skeleton& sk) {
  const auto has_all = [&sk](std::initializer_list<std::string_view> names) {
    return std::all_of(names.begin(), names.end(),
                       [&sk](std::string_view n) { return sk.FindJoint(n) >= 0; });
  };
  if (has_all({"Hips", "Hand_L", "Hand_R", "UpperLeg_L", "UpperLeg_R", "Toes_L", "Toes_R"})) {
    return SkeletonFamily::kBandai22;
  }
  if (has_all({"CC_Base_Hip", "CC_Base_L_Hand", "CC_Base_R_Hand", "CC_Base_L_Foot",
               "CC_Base_R_Foot"})) {
    return SkeletonFamily::kCmuIclone100;
  }
  if (has_all({"LHipJoint", "RHipJoint", "lowerback", "LeftWrist", "RightWrist", "LeftAnkle",
               "RightAnkle"})) {
    return SkeletonFamily::kCmu31;
  }
  if (has_all({"pelvis", "spine3", "left_collar", "left_wrist", "right_wrist", "left_ankle",
               "right_ankle"})) {
    return SkeletonFamily::kSmplx55;
  }
  return SkeletonFamily::kUnknown;
}

bool GlobMatch(std::string_view pattern, std::string_view text) {
  size_t p = 0, t = 0;
  size_t star_p = std::string_view::npos, star_t = 0;
  while (t < text.size()) {
    if (p < pattern.size() &&
        (pattern[p] == '?' || internal::AsciiLower(pattern[p]) == internal::AsciiLower(text[t]))) {
      ++p;
      ++t;
    } else if (p < pattern.size() && pattern[p] == '*') {
      star_p = p++;
      star_t = t;
    } else if (star_p != std::string_view::npos) {
      p = star_p + 1;
      t = ++star_t;
    } else {
      return false;
    }
  }
  while (p < pattern.size() && pattern[p] == '*') ++p;
  return p == pattern.size();
}

StatusOr<BodyRegionRules> BodyRegionRules::Parse(std::string_view text,
                                                 std::string_view source_name) {
  std::vector<Rule> rules;
  int line_no = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    ++line_no;
    if (const size_t hash = line.find('#'); hash != std::string_view::npos) {
      line = line.substr(0, hash);
    }
    line = internal::Trim(line);
    if (line.empty()) continue;
    // The region is the last word; the pattern is everything before it.
    const size_t split = line.find_last_of(" \t");
    if (split == std::string_view::npos) {
      return absl::InvalidArgumentError(kinemo::StrCat(
          source_name, ":", line_no, ": expected 'pattern region', got '", line, "'"));
    }
    const std::string_view pattern = internal::Trim(line.substr(0, split));
    const std::string_view region_name = line.substr(split + 1);
    const std::optional<BodyRegion> region = ParseBodyRegion(region_name);
    if (!region) {
      return absl::InvalidArgumentError(
          kinemo::StrCat(source_name, ":", line_no, ": unknown region '", region_name,
                         "' (expected one of ", Join(kRegionNames, ", "), ")"));
    }
    rules.push_back({std::string(pattern), *region});
  }
  return BodyRegionRules(std::move(rules));
}

StatusOr<BodyRegionRules> BodyRegionRules::LoadFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return absl::NotFoundError(kinemo::StrCat(path, ": cannot open"));
  std::ostringstream ss;
  ss << f.rdbuf();
  if (ss.str().size() > (1u << 20)) {
    return absl::InvalidArgumentError(kinemo::StrCat(path, ": larger than 1 MiB"));
  }
  return Parse(ss.str(), path);
}

BodyRegionRules BodyRegionRules::FromMap(
    const std::map<std::string, BodyRegion, std::less<>>& names) {
  std::vector<Rule> rules;
  rules.reserve(names.size());
  for (const auto& [name, region] : names) rules.push_back({name, region});
  return BodyRegionRules(std::move(rules));
}

const BodyRegionRules& BodyRegionRules::ForFamily(SkeletonFamily family) {
  static const BodyRegionRules* const bandai =
      new BodyRegionRules(MustParse(kBandai22Rules, "bandai22"));
  static const BodyRegionRules* const iclone =
      new BodyRegionRules(MustParse(kCmuIcloneRules, "cmu_iclone100"));
  static const BodyRegionRules* const cmu31 = new BodyRegionRules(MustParse(kCmu31Rules, "cmu31"));
  static const BodyRegionRules* const smplx = new BodyRegionRules(MustParse(kSmplx55Rules, "smplx55"));
  switch (family) {
    case SkeletonFamily::kBandai22:
      return *bandai;
    case SkeletonFamily::kCmuIclone100:
      return *iclone;
    case SkeletonFamily::kCmu31:
      return *cmu31;
    case SkeletonFamily::kSmplx55:
      return *smplx;
    case SkeletonFamily::kUnknown:
      break;
  }
  return GenericBodyRegionRules();
}

const BodyRegionRules& GenericBodyRegionRules() {
  static const BodyRegionRules* const generic = new BodyRegionRules({}, /*name_heuristics=*/true);
  return *generic;
}

std::optional<BodyRegion> BodyRegionRules::Match(std::string_view joint_name) const {
  for (const Rule& r : rules_) {
    if (GlobMatch(r.pattern, joint_name)) return r.region;
  }
  if (name_heuristics_) return GuessRegion(joint_name);
  return std::nullopt;
}

std::vector<int> BodyRegionMap::JointsIn(BodyRegion r) const {
  std::vector<int> out;
  for (size_t j = 0; j < region.size(); ++j) {
    if (region[j] == r) out.push_back(static_cast<int>(j));
  }
  return out;
}

int BodyRegionMap::num_from_rule() const {
  return static_cast<int>(std::count(from_rule.begin(), from_rule.end(), true));
}

BodyRegionMap MapBodyRegions(const Skeleton& skeleton, const BodyRegionRules& rules) {
  BodyRegionMap map;
  map.family = DetectSkeletonFamily(skeleton);
  const size_t n = static_cast<size_t>(skeleton.num_joints());
  map.region.resize(n, BodyRegion::kTrunk);
  map.from_rule.resize(n, false);
  for (size_t j = 0; j < n; ++j) {
    const Joint& joint = skeleton.joint(static_cast<int>(j));
    if (const std::optional<BodyRegion> r = rules.Match(joint.name)) {
      map.region[j] = *r;
      map.from_rule[j] = true;
    } else if (joint.parent >= 0) {
      map.region[j] = map.region[static_cast<size_t>(joint.parent)];  // parents come first
    }
  }
  return map;
}

BodyRegionMap MapBodyRegions(const Skeleton& skeleton) {
  return MapBodyRegions(skeleton, BodyRegionRules::ForFamily(DetectSkeletonFamily(skeleton)));
}

StatusOr<KeyJoints> FindKeyJoints(const Skeleton& sk, const BodyRegionMap& map) {
  if (map.region.size() != static_cast<size_t>(sk.num_joints())) {
    return InvalidField("body_region_map", map.region.size(), " joints, skeleton has ",
                        sk.num_joints());
  }
  KeyJoints k;
  k.head = ShallowestNamed(sk, map, BodyRegion::kHead, -1, {"head"});
  if (k.head < 0) k.head = TopmostIn(sk, map, BodyRegion::kHead);
  k.left_hand = TopmostIn(sk, map, BodyRegion::kLeftHand);
  k.right_hand = TopmostIn(sk, map, BodyRegion::kRightHand);
  k.left_foot = ShallowestNamed(sk, map, BodyRegion::kLeftLeg, -1, {"foot", "ankle"});
  k.right_foot = ShallowestNamed(sk, map, BodyRegion::kRightLeg, -1, {"foot", "ankle"});
  // The toe: a "toe" joint below the foot; else, below an ankle, the joint
  // named "foot" or "ball" (SMPL-X calls the ball of the foot left_foot).
  const auto toe_under = [&](BodyRegion leg, int foot) {
    if (foot < 0) return -1;
    const int toe = ShallowestNamed(sk, map, leg, foot, {"toe"});
    return toe >= 0 ? toe : ShallowestNamed(sk, map, leg, foot, {"foot", "ball"});
  };
  k.left_toe = toe_under(BodyRegion::kLeftLeg, k.left_foot);
  k.right_toe = toe_under(BodyRegion::kRightLeg, k.right_foot);
  std::vector<std::string_view> missing;
  if (k.head < 0) missing.push_back("head");
  if (k.left_hand < 0) missing.push_back("left hand");
  if (k.right_hand < 0) missing.push_back("right hand");
  if (k.left_foot < 0) missing.push_back("left foot");
  if (k.right_foot < 0) missing.push_back("right foot");
  if (!missing.empty()) {
    return absl::NotFoundError(kinemo::StrCat("skeleton (", SkeletonFamilyName(map.family),
                                              "): no ", Join(missing, ", "), " joint"));
  }
  return k;
}

}  // namespace kinemo::motion
