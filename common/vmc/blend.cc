#include "common/vmc/blend.h"

#include <algorithm>

namespace kinemo::vmc {
namespace {

constexpr std::array<std::string_view, kNumBlendShapes> kVrm0Shapes = {
    "A", "I", "U", "E", "O", "Blink", "Blink_L", "Blink_R", "Joy", "Angry", "Sorrow", "Fun", "Surprised"};
constexpr std::array<std::string_view, kNumBlendShapes> kVrm1Shapes = {
    "aa", "ih", "ou", "ee", "oh", "blink", "blinkLeft", "blinkRight", "happy", "angry", "sad", "relaxed", "surprised"};

enum BlendShape { kA, kI, kU, kE, kO, kBlink, kBlinkL, kBlinkR, kJoy, kAngry, kSorrow, kFun, kSurprised };

float Unit(float v) { return std::clamp(v, 0.0f, 1.0f); }

}  // namespace

StatusOr<BlendNaming> ParseBlendNaming(std::string_view text, std::string_view field) {
  if (text == "vrm0") return BlendNaming::kVrm0;
  if (text == "vrm1") return BlendNaming::kVrm1;
  return InvalidField(field, "'", text, "' is not vrm0 or vrm1");
}

const std::array<std::string_view, kNumBlendShapes>& BlendShapeNames(BlendNaming naming) {
  return naming == BlendNaming::kVrm0 ? kVrm0Shapes : kVrm1Shapes;
}

BlendWeights FaceBlendWeights(const face::FaceFrame& f) {
  using face::OvrViseme;
  BlendWeights w{};
  auto ovr = [&](OvrViseme v) { return Unit(f.ovr[static_cast<int>(v)]); };
  w[kA] = ovr(OvrViseme::kAA);
  w[kI] = ovr(OvrViseme::kIH);
  w[kU] = ovr(OvrViseme::kOU);
  w[kE] = ovr(OvrViseme::kE);
  w[kO] = ovr(OvrViseme::kOH);
  const float left = Unit(f.blink_left), right = Unit(f.blink_right);
  const float both = std::min(left, right);
  w[kBlink] = both;
  w[kBlinkL] = left - both;
  w[kBlinkR] = right - both;
  const float e = Unit(f.expression_weight);
  switch (f.expression) {
    case face::Expression::kHappy: w[kJoy] = e; break;
    case face::Expression::kAngry: w[kAngry] = e; break;
    case face::Expression::kSad: w[kSorrow] = e; break;
    case face::Expression::kSurprised: w[kSurprised] = e; break;
    case face::Expression::kNeutral: break;
  }
  return w;
}

}  // namespace kinemo::vmc
