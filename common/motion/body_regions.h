// Body regions of a skeleton's joints, and the key joints later stages need
// (head, hands/wrists, feet, toes).
//
// Built-in maps cover the three skeletons of kinemo's motion data:
//   bandai22       Bandai-Namco dataset-1 (joint_Root, Hips, ..., Toes_R)
//   cmu_iclone100  CMU mocap retargeted to iClone/Character Creator
//                  (RL_BoneRoot, CC_Base_*; 100 joints, 99 without RL_BoneRoot)
//   cmu31          CMU mocap, cgspeed BVH conversion (Hips, LHipJoint, ..., RThumb)
//   smplx55        the SMPL-X joint tree (pelvis, spine1-3, ..., jaw, eyes, 15
//                  finger joints per hand) as BEAT2 exports it
// Other skeletons: rules from a text file of "pattern region" lines, a map of
// joint names, or name heuristics (GenericBodyRegionRules()).
//
// Neck joints belong to the head region; clavicles/collars to the arm;
// wrists and fingers to the hand; hips (thigh roots), feet and toes to the leg.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::motion {

enum class BodyRegion : uint8_t {
  kHead,
  kTrunk,
  kLeftArm,
  kRightArm,
  kLeftHand,
  kRightHand,
  kLeftLeg,
  kRightLeg,
};
inline constexpr int kNumBodyRegions = 8;

// "head", "trunk", "left_arm", "right_arm", "left_hand", "right_hand",
// "left_leg", "right_leg".
std::string_view BodyRegionName(BodyRegion region);
std::optional<BodyRegion> ParseBodyRegion(std::string_view name);

enum class SkeletonFamily : uint8_t { kUnknown, kBandai22, kCmuIclone100, kCmu31, kSmplx55 };

// "unknown", "bandai22", "cmu_iclone100", "cmu31", "smplx55".
std::string_view SkeletonFamilyName(SkeletonFamily family);

// Recognises the four built-in skeletons by their joint names.
SkeletonFamily DetectSkeletonFamily(const Skeleton& skeleton);

// Ordered rules: the first rule whose pattern matches a joint name gives the
// joint's region. Patterns are globs ('*' any run, '?' one character),
// matched case-insensitively against the whole name.
class BodyRegionRules {
 public:
  struct Rule {
    std::string pattern;
    BodyRegion region;
  };

  BodyRegionRules() = default;
  explicit BodyRegionRules(std::vector<Rule> rules, bool name_heuristics = false)
      : rules_(std::move(rules)), name_heuristics_(name_heuristics) {}

  // One "pattern region" per line; '#' starts a comment; blank lines are
  // skipped. Errors name source_name:line.
  static StatusOr<BodyRegionRules> Parse(std::string_view text, std::string_view source_name);
  static StatusOr<BodyRegionRules> LoadFile(const std::string& path);
  // Exact joint names (no wildcards).
  static BodyRegionRules FromMap(const std::map<std::string, BodyRegion, std::less<>>& names);
  // The built-in rules of a family (name heuristics for kUnknown).
  static const BodyRegionRules& ForFamily(SkeletonFamily family);

  // The region of a joint name: the first matching rule, else (when
  // name_heuristics()) a guess from words in the name such as left/right,
  // hand, wrist, finger, arm, leg, foot, head; nullopt when nothing applies.
  std::optional<BodyRegion> Match(std::string_view joint_name) const;

  std::span<const Rule> rules() const { return rules_; }
  bool name_heuristics() const { return name_heuristics_; }

 private:
  std::vector<Rule> rules_;
  bool name_heuristics_ = false;
};

// Rules that use only name heuristics (for unknown skeletons).
const BodyRegionRules& GenericBodyRegionRules();

// Glob match ('*', '?'), case-insensitive; exposed for tests.
bool GlobMatch(std::string_view pattern, std::string_view text);

struct BodyRegionMap {
  SkeletonFamily family = SkeletonFamily::kUnknown;
  std::vector<BodyRegion> region;  // per joint
  std::vector<bool> from_rule;     // false: inherited from the parent (trunk for a root)

  std::vector<int> JointsIn(BodyRegion r) const;
  int num_from_rule() const;
};

// Maps every joint: its rule, else its parent's region, else trunk.
BodyRegionMap MapBodyRegions(const Skeleton& skeleton, const BodyRegionRules& rules);
// Detects the family and uses its built-in rules.
BodyRegionMap MapBodyRegions(const Skeleton& skeleton);

struct KeyJoints {
  int head = -1;       // the head joint (not the neck)
  int left_hand = -1;  // the wrist: topmost joint of the hand region
  int right_hand = -1;
  int left_foot = -1;  // the ankle/foot joint
  int right_foot = -1;
  int left_toe = -1;  // optional: a toe joint below the foot, -1 if none
  int right_toe = -1;
};

// Finds the key joints from a region map. Fails, naming what is missing, when
// the head, either hand or either foot cannot be found.
StatusOr<KeyJoints> FindKeyJoints(const Skeleton& skeleton, const BodyRegionMap& map);

}  // namespace kinemo::motion
