#include "common/vmc/blend.h"

#include <algorithm>
#include <optional>

#include "common/retarget/face_map.h"

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
  // Mouth and expression: the recipes a VRM rig's presets get (retarget's
  // face map), looked up once by the VRM 1.0 names (0.x's are the same
  // recipes). Blinks are split here (see blend.h).
  static const std::array<std::optional<retarget::FaceControl>, kNumBlendShapes> kControls = [] {
    std::array<std::optional<retarget::FaceControl>, kNumBlendShapes> c;
    for (int k : {kA, kI, kU, kE, kO, kJoy, kAngry, kSorrow, kFun, kSurprised})
      c[static_cast<size_t>(k)] = retarget::VrmPresetControl(kVrm1Shapes[static_cast<size_t>(k)], true);
    return c;
  }();
  std::array<float, retarget::kNumFaceInputs> in;
  retarget::FaceInputs(f, in);
  BlendWeights w{};
  for (size_t k = 0; k < kControls.size(); ++k)
    if (kControls[k]) w[k] = retarget::ControlWeight(*kControls[k], in);
  const float left = Unit(f.blink_left), right = Unit(f.blink_right);
  const float both = std::min(left, right);
  w[kBlink] = both;
  w[kBlinkL] = left - both;
  w[kBlinkR] = right - both;
  return w;
}

}  // namespace kinemo::vmc
