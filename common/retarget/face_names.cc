// The morph-name families the face map knows (face_names.h): OVR / OpenXR
// visemes, Rocketbox / VALID head morphs, ARKit's 52 blend shapes, VRM
// expressions (0.x presets and 1.0 names) and plain names, each as the
// recipe that drives a control from the face inputs.
#include "common/retarget/face_names.h"

#include <cctype>
#include <cstdio>
#include <map>

namespace kinemo::retarget::face_names {

namespace {

Recipe Mouth(std::vector<FaceTerm> t) { return {"mouth", std::move(t), true}; }
Recipe Lips(std::vector<FaceTerm> t) { return {"mouth", std::move(t), false}; }  // closing shapes: not gated
Recipe Eyes(std::vector<FaceTerm> t) { return {"eyes", std::move(t), false}; }
Recipe Brows(std::vector<FaceTerm> t) { return {"brows", std::move(t), false}; }
Recipe Expr(std::vector<FaceTerm> t) { return {"expression", std::move(t), false}; }

// The many-to-one table OVR -> five vowels (VRM a i u e o / aa ih ou ee oh,
// plain vowel shapes), docs/retarget.md.
const std::map<char, Recipe>& VowelTable() {
  static const std::map<char, Recipe> t = {
      {'a', Mouth({{kAA, 1}, {kTH, 0.2f}, {kDD, 0.3f}, {kKK, 0.4f}, {kNN, 0.2f}})},
      {'i', Mouth({{kIH, 1}, {kFF, 0.3f}, {kTH, 0.3f}, {kDD, 0.3f}, {kCH, 0.3f}, {kSS, 0.6f}, {kNN, 0.3f}})},
      {'u', Mouth({{kOU, 1}, {kCH, 0.5f}, {kRR, 0.4f}})},
      {'e', Mouth({{kE, 1}, {kKK, 0.2f}})},
      {'o', Mouth({{kOH, 1}, {kRR, 0.3f}})},
  };
  return t;
}

}  // namespace

std::string Lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

namespace {

// The part of a morph name after its last '.' ("h_expressions.AE_AA_h" ->
// "AE_AA_h"; Blender / Maya exports prefix the blend shape node).
std::string_view AfterDot(std::string_view name) {
  const size_t dot = name.rfind('.');
  return dot == std::string_view::npos ? name : name.substr(dot + 1);
}

}  // namespace

// OVR / OpenXR: viseme_sil .. viseme_U (Ready Player Me: viseme_I/O/U).
std::optional<Recipe> OvrRecipe(std::string_view name) {
  const std::string key = Lower(AfterDot(name));
  if (key.rfind("viseme_", 0) != 0) return std::nullopt;
  static const std::map<std::string, int, std::less<>> kNames = {
      {"sil", kSil}, {"pp", kPP}, {"ff", kFF}, {"th", kTH}, {"dd", kDD}, {"kk", kKK}, {"ch", kCH}, {"ss", kSS},
      {"nn", kNN},   {"rr", kRR}, {"aa", kAA}, {"e", kE},   {"ih", kIH}, {"i", kIH},  {"oh", kOH}, {"o", kOH},
      {"ou", kOU},   {"u", kOU}};
  const auto it = kNames.find(key.substr(7));
  if (it == kNames.end()) return std::nullopt;
  if (it->second == kSil) return Recipe{"mouth", {}, false};  // the rest shape: nothing to add
  if (it->second == kPP) return Lips({{kPP, 1}});
  return Mouth({{it->second, 1}});
}

// Rocketbox / VALID head morphs: "h_expressions.<X>_h".
std::string RocketboxBase(std::string_view name) {
  std::string_view base = AfterDot(name);
  if (base.size() > 2 && base.substr(base.size() - 2) == "_h") base.remove_suffix(2);
  return std::string(base);
}

bool IsRocketboxName(std::string_view name) {
  return name.rfind("h_expressions.", 0) == 0 || name.rfind("h_teeth.", 0) == 0;
}

std::optional<Recipe> RocketboxRecipe(const std::string& base) {
  static const std::map<std::string, Recipe, std::less<>> kTable = {
      {"AE_AA", Mouth({{kAA, 1}})},
      {"AO_a", Mouth({{kOH, 0.8f}, {kAA, 0.2f}})},
      {"Ax_E", Mouth({{kE, 0.8f}, {kNN, 0.3f}, {kRR, 0.2f}})},
      {"TD_I", Mouth({{kDD, 0.8f}, {kIH, 0.6f}, {kNN, 0.5f}, {kTH, 0.3f}})},
      {"UH_OO", Mouth({{kOU, 0.5f}, {kOH, 0.2f}, {kRR, 0.4f}})},
      {"UW_U", Mouth({{kOU, 0.8f}})},
      {"H_EST", Mouth({{kIH, 0.4f}, {kE, 0.3f}, {kKK, 0.3f}})},
      {"FV", Mouth({{kFF, 1}})},
      {"S", Mouth({{kSS, 1}, {kTH, 0.4f}})},
      {"SH_CH", Mouth({{kCH, 1}})},
      {"MPB_Up", Lips({{kPP, 1}})},
      {"MPB_Down", Lips({{kPP, 1}})},
      {"KG", Mouth({{kKK, 1}})},
      {"MouthOpen", Mouth({{kJaw, 0.5f}})},
      {"ReyeClose", Eyes({{kBlinkR, 1}})},
      {"LeyeClose", Eyes({{kBlinkL, 1}})},
      {"ReyeOpen", Eyes({{kSurprised, 0.5f}})},
      {"LeyeOpen", Eyes({{kSurprised, 0.5f}})},
      {"RbrowUp", Brows({{kBrow, 0.7f}, {kSurprised, 0.7f}})},
      {"LbrowUp", Brows({{kBrow, 0.7f}, {kSurprised, 0.7f}})},
      {"RRbrowUp", Brows({{kBrow, 0.5f}, {kSurprised, 0.5f}})},
      {"LLbrowUp", Brows({{kBrow, 0.5f}, {kSurprised, 0.5f}})},
      {"RbrowDown", Brows({{kAngry, 0.7f}})},
      {"LbrowDown", Brows({{kAngry, 0.7f}})},
      {"RsmileClose", Expr({{kHappy, 0.7f}})},
      {"LsmileClose", Expr({{kHappy, 0.7f}})},
      {"RsmileOpen", Expr({{kHappy, 0.3f}})},
      {"LsmileOpen", Expr({{kHappy, 0.3f}})},
      {"RmouthSad", Expr({{kSad, 0.7f}})},
      {"LmouthSad", Expr({{kSad, 0.7f}})},
      {"Rsad", Expr({{kSad, 0.5f}})},
      {"Lsad", Expr({{kSad, 0.5f}})},
      {"Rdisgust", Expr({{kAngry, 0.3f}})},
      {"Ldisgust", Expr({{kAngry, 0.3f}})},
      {"Rsquint", Expr({{kHappy, 0.3f}})},
      {"Lsquint", Expr({{kHappy, 0.3f}})},
  };
  const auto it = kTable.find(base);
  if (it == kTable.end()) return std::nullopt;
  return it->second;
}

namespace {

// ARKit's 52 blend shapes: lower-cased, "_L"/"_R" spelled "left"/"right".
std::string ArkitKey(std::string_view name) {
  std::string key = Lower(AfterDot(name));
  if (key.size() > 2 && key[key.size() - 2] == '_' && (key.back() == 'l' || key.back() == 'r')) {
    key = key.substr(0, key.size() - 2) + (key.back() == 'l' ? "left" : "right");
  }
  key.erase(std::remove(key.begin(), key.end(), '_'), key.end());
  return key;
}

}  // namespace

std::optional<Recipe> ArkitRecipe(std::string_view name) {
  static const std::map<std::string, Recipe, std::less<>> kTable = [] {
    std::map<std::string, Recipe, std::less<>> t = {
        {"jawopen", Mouth({{kJaw, 1}})},
        {"mouthclose", Recipe{"mouth", {}, false}},
        {"mouthfunnel", Mouth({{kOH, 0.7f}, {kOU, 0.4f}, {kCH, 0.5f}})},
        {"mouthpucker", Mouth({{kOU, 0.8f}, {kOH, 0.3f}, {kRR, 0.3f}})},
        {"mouthrolllower", Lips({{kFF, 0.7f}})},
        {"mouthrollupper", Lips({{kPP, 0.3f}})},
        {"mouthshrugupper", Recipe{"mouth", {}, false}},
        {"mouthshruglower", Recipe{"mouth", {}, false}},
        {"tongueout", Mouth({{kTH, 0.5f}})},
        {"browinnerup", Brows({{kBrow, 0.8f}, {kSad, 0.5f}, {kSurprised, 0.6f}})},
        {"jawforward", Recipe{"mouth", {}, false}},
        {"cheekpuff", Recipe{"expression", {}, false}},
    };
    for (const char* side : {"left", "right"}) {
      const std::string s = side;
      const int blink = s == "left" ? kBlinkL : kBlinkR;
      t.emplace("mouthpress" + s, Lips({{kPP, 0.6f}}));
      t.emplace("mouthupperup" + s, Mouth({{kFF, 0.3f}, {kSS, 0.2f}}));
      t.emplace("mouthlowerdown" + s, Mouth({{kAA, 0.4f}, {kE, 0.3f}}));
      t.emplace("mouthstretch" + s, Mouth({{kE, 0.4f}, {kIH, 0.4f}, {kSS, 0.3f}, {kDD, 0.2f}}));
      t.emplace("mouthsmile" + s, Expr({{kHappy, 0.8f}}));
      t.emplace("mouthfrown" + s, Expr({{kSad, 0.6f}, {kAngry, 0.3f}}));
      t.emplace("mouthdimple" + s, Expr({{kHappy, 0.3f}}));
      t.emplace("cheeksquint" + s, Expr({{kHappy, 0.4f}}));
      t.emplace("nosesneer" + s, Expr({{kAngry, 0.5f}}));
      t.emplace("browdown" + s, Brows({{kAngry, 0.8f}}));
      t.emplace("browouterup" + s, Brows({{kBrow, 0.6f}, {kSurprised, 0.8f}}));
      t.emplace("eyeblink" + s, Eyes({{blink, 1}}));
      t.emplace("eyewide" + s, Eyes({{kSurprised, 0.6f}}));
      t.emplace("eyesquint" + s, Eyes({{kHappy, 0.3f}}));
      t.emplace("mouth" + s, Recipe{"mouth", {}, false});
      for (const char* look : {"lookup", "lookdown", "lookin", "lookout"}) t.emplace("eye" + std::string(look) + s, Recipe{"eyes", {}, false});
    }
    return t;
  }();
  const auto it = kTable.find(ArkitKey(name));
  if (it == kTable.end()) return std::nullopt;
  return it->second;
}

// Plain names (any case, '_' '-' ' ' ignored): expressions, blinks, vowels.
std::optional<Recipe> NamesRecipe(std::string_view name) {
  std::string key = Lower(AfterDot(name));
  key.erase(std::remove_if(key.begin(), key.end(), [](char c) { return c == '_' || c == '-' || c == ' '; }), key.end());
  static const std::map<std::string, char, std::less<>> kVowels = {
      {"a", 'a'}, {"aa", 'a'}, {"ah", 'a'}, {"i", 'i'}, {"ih", 'i'}, {"ii", 'i'}, {"u", 'u'}, {"ou", 'u'},
      {"uu", 'u'}, {"e", 'e'}, {"ee", 'e'}, {"eh", 'e'}, {"o", 'o'}, {"oh", 'o'}};
  if (auto v = kVowels.find(key); v != kVowels.end()) return VowelTable().at(v->second);
  static const std::map<std::string, Recipe, std::less<>> kTable = {
      {"happy", Expr({{kHappy, 1}})},        {"joy", Expr({{kHappy, 1}})},
      {"smile", Expr({{kHappy, 1}})},        {"angry", Expr({{kAngry, 1}})},
      {"anger", Expr({{kAngry, 1}})},        {"sad", Expr({{kSad, 1}})},
      {"sorrow", Expr({{kSad, 1}})},         {"surprised", Expr({{kSurprised, 1}})},
      {"surprise", Expr({{kSurprised, 1}})}, {"blink", Eyes({{kBlinkL, 0.5f}, {kBlinkR, 0.5f}})},
      {"blinkleft", Eyes({{kBlinkL, 1}})},   {"blinkl", Eyes({{kBlinkL, 1}})},
      {"blinkright", Eyes({{kBlinkR, 1}})},  {"blinkr", Eyes({{kBlinkR, 1}})},
      {"mouthopen", Mouth({{kJaw, 1}})},     {"browsup", Brows({{kBrow, 1}})},
      {"browup", Brows({{kBrow, 1}})},
  };
  const auto it = kTable.find(key);
  if (it == kTable.end()) return std::nullopt;
  return it->second;
}

// VRM 0.x preset -> the name VMC receivers use.
std::string Vrm0VmcName(const std::string& preset, const std::string& group_name) {
  static const std::map<std::string, std::string, std::less<>> kNames = {
      {"a", "A"},         {"i", "I"},           {"u", "U"},           {"e", "E"},
      {"o", "O"},         {"blink", "Blink"},   {"blink_l", "Blink_L"}, {"blink_r", "Blink_R"},
      {"joy", "Joy"},     {"angry", "Angry"},   {"sorrow", "Sorrow"}, {"fun", "Fun"},
      {"neutral", "Neutral"}, {"lookup", "LookUp"}, {"lookdown", "LookDown"}, {"lookleft", "LookLeft"},
      {"lookright", "LookRight"}};
  const auto it = kNames.find(preset);
  return it != kNames.end() ? it->second : group_name;
}

// The recipe of a VRM expression (0.x presetName or 1.0 name), nullopt when
// kinemo has nothing for it (fun, relaxed, neutral, look*).
std::optional<Recipe> VrmRecipe(const std::string& name, bool has_left_right_blinks) {
  static const std::map<std::string, char, std::less<>> kVowels = {
      {"a", 'a'}, {"i", 'i'}, {"u", 'u'}, {"e", 'e'}, {"o", 'o'},
      {"aa", 'a'}, {"ih", 'i'}, {"ou", 'u'}, {"ee", 'e'}, {"oh", 'o'}};
  if (auto v = kVowels.find(name); v != kVowels.end()) return VowelTable().at(v->second);
  if (name == "blink") {
    if (has_left_right_blinks) return std::nullopt;
    return Eyes({{kBlinkL, 0.5f}, {kBlinkR, 0.5f}});
  }
  if (name == "blink_l" || name == "blinkLeft") return Eyes({{kBlinkL, 1}});
  if (name == "blink_r" || name == "blinkRight") return Eyes({{kBlinkR, 1}});
  if (name == "joy" || name == "happy") return Expr({{kHappy, 1}});
  if (name == "angry") return Expr({{kAngry, 1}});
  if (name == "sorrow" || name == "sad") return Expr({{kSad, 1}});
  if (name == "surprised") return Expr({{kSurprised, 1}});
  return std::nullopt;
}

std::string FormatCoefficient(float c) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", static_cast<double>(c));
  return buf;
}

}  // namespace kinemo::retarget::face_names
