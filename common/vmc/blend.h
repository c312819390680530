// The face of a frame (common/face/face_frame.h) as VRM blend shapes, the
// names a VMC receiver applies with /VMC/Ext/Blend/Val (docs/vmc.md):
//
//   VRM 0.x presets  A I U E O  Blink Blink_L Blink_R  Joy Angry Sorrow Fun  Surprised
//   VRM 1.0 presets  aa ih ou ee oh  blink blinkLeft blinkRight  happy angry sad relaxed  surprised
//
// Mouth and expression: the recipes a VRM rig's presets get from kinemo's
// face map (retarget::VrmPresetControl; docs/retarget.md "Faces: the talking
// face onto the rig's own controls", its table "Many-to-one: OVR → five
// vowels"): each vowel from its viseme and a share of the consonants
// shaped like it, all x (1 - PP); silence leaves the mouth at rest. Eyes: the closure both
// eyes share on Blink/blink, each eye's remainder on its own shape (so one
// eye's total is its closure when the receiver adds them). Expression: its
// weight on the matching shape (neutral: none; surprised: VRM 1.0's preset,
// a custom clip of that name on VRM 0.x models that have one). Fun/relaxed
// has no kinemo expression and is sent as 0. Every name is sent on every
// frame with a face, so a shape the face leaves returns to 0.
#pragma once

#include <array>
#include <string_view>

#include "common/face/face_frame.h"
#include "common/status/status.h"

namespace kinemo::vmc {

enum class BlendNaming { kVrm0, kVrm1 };

// "vrm0" | "vrm1"; INVALID_ARGUMENT naming `field` otherwise.
StatusOr<BlendNaming> ParseBlendNaming(std::string_view text, std::string_view field);

inline constexpr int kNumBlendShapes = 13;
using BlendWeights = std::array<float, kNumBlendShapes>;

// The names, in the order of BlendWeights.
const std::array<std::string_view, kNumBlendShapes>& BlendShapeNames(BlendNaming naming);

// The weights of one face frame, each in [0, 1].
BlendWeights FaceBlendWeights(const face::FaceFrame& frame);

}  // namespace kinemo::vmc
