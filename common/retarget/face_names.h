// The morph-name families the face map knows, as recipes: how the face
// inputs drive a control named in OVR / OpenXR (viseme_*), Rocketbox / VALID
// ("h_expressions.<X>_h"), ARKit (52 blend shapes), VRM (0.x presets, 1.0
// expressions) or plain terms (docs/retarget.md "Face map files"). Internal
// to kinemo_retarget: face_map.cc uses it.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/retarget/face_map.h"

namespace kinemo::retarget::face_names {

// Input shorthands for the recipe tables.
enum : int {
  kSil = 0, kPP, kFF, kTH, kDD, kKK, kCH, kSS, kNN, kRR, kAA, kE, kIH, kOH, kOU,
  kJaw = kInputJaw, kBlinkL = kInputBlinkLeft, kBlinkR = kInputBlinkRight, kBrow = kInputBrowRaise,
  kHappy = kInputHappy, kAngry = kInputAngry, kSad = kInputSad, kSurprised = kInputSurprised,
};

// A way to drive one control: its group, terms, and whether B/P/M close it.
struct Recipe {
  std::string_view group;
  std::vector<FaceTerm> terms;
  bool gate = false;
};

// Lower-cased (ASCII).
std::string Lower(std::string_view s);
// OVR / OpenXR: viseme_sil .. viseme_U (Ready Player Me: viseme_I/O/U).
std::optional<Recipe> OvrRecipe(std::string_view name);
// Rocketbox / VALID head morphs: "h_expressions.<X>_h" -> "<X>".
std::string RocketboxBase(std::string_view name);
bool IsRocketboxName(std::string_view name);
std::optional<Recipe> RocketboxRecipe(const std::string& base);
// ARKit's 52 blend shapes ("_L"/"_R" or "Left"/"Right", any case).
std::optional<Recipe> ArkitRecipe(std::string_view name);
// Plain names (any case, '_' '-' ' ' ignored): expressions, blinks, vowels.
std::optional<Recipe> NamesRecipe(std::string_view name);
// VRM 0.x preset -> the name VMC receivers use.
std::string Vrm0VmcName(const std::string& preset, const std::string& group_name);
// The recipe of a VRM expression (0.x presetName or 1.0 name), nullopt when
// the name is none kinemo drives.
std::optional<Recipe> VrmRecipe(const std::string& name, bool has_left_right_blinks);
// A term's coefficient as text ("%g").
std::string FormatCoefficient(float c);

}  // namespace kinemo::retarget::face_names
