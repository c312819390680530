// The face of a talking character at one instant, in plain C++ (the core's
// form of kinemo.common.v1.FaceFrame, proto/kinemo/common/v1/face.proto):
// rig-neutral channels on the body's clock, one face frame per motion frame.
// Producers: the face track of speech animation. Consumers: BVH jaw, viseme
// files, the rig's face mapping (common/retarget), VMC, the studio.
#pragma once

#include <array>
#include <string_view>
#include <vector>

namespace kinemo::face {

inline constexpr int kNumOvrVisemes = 15;
inline constexpr int kNumCategories = 15;  // thesis Table 4.5

// The OVR / OpenXR viseme names, in FaceFrame::ovr order (proto OvrViseme - 1).
inline constexpr std::array<std::string_view, kNumOvrVisemes> kOvrVisemeNames = {
    "sil", "PP", "FF", "TH", "DD", "kk", "CH", "SS", "nn", "RR", "aa", "E", "ih", "oh", "ou"};

enum class OvrViseme { kSil, kPP, kFF, kTH, kDD, kKK, kCH, kSS, kNN, kRR, kAA, kE, kIH, kOH, kOU };

// Proto FaceExpression - 1 (kNeutral = FACE_EXPRESSION_NEUTRAL).
enum class Expression { kNeutral, kHappy, kAngry, kSad, kSurprised };
inline constexpr std::array<std::string_view, 5> kExpressionNames = {"neutral", "happy", "angry", "sad",
                                                                      "surprised"};

struct FaceFrame {
  double time_s = 0;
  // OVR viseme weights (sum 1; all zero = no speech analysis, a still mouth).
  std::array<float, kNumOvrVisemes> ovr{};
  // Thesis Table 4.5 category weights, proto VisemeCategory order minus 1.
  std::array<float, kNumCategories> categories{};
  float jaw_open_deg = 0;  // 0 = closed, positive = open
  // False for a frame read from a viseme file without jaw_deg (an older
  // file): the rig mapping then draws the vowels at their weights instead of
  // opening them with the jaw (common/retarget/face_map.h). Not on the wire.
  bool jaw_known = true;
  float blink_left = 0, blink_right = 0;  // 0 open .. 1 closed
  float brow_raise = 0;                   // 0 .. 1
  Expression expression = Expression::kNeutral;
  float expression_weight = 0;  // 0 .. 1
  float emphasis = 0;           // -1 .. 1 (thesis §4.5.2)
};

// Face frames at a fixed rate (the motion's): frames[i].time_s = i * frame_time_s.
struct FaceTrack {
  double frame_time_s = 1.0 / 30.0;
  std::vector<FaceFrame> frames;
};

}  // namespace kinemo::face
