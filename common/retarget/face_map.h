// A talking face onto a rig's own face controls (docs/retarget.md "Faces").
//
// A face::FaceFrame is rig-neutral (OVR visemes, jaw opening in degrees,
// blinks, brows, an expression). A FaceMap, made once per rig, says which of
// the rig's controls are driven and how:
// - morph targets recognised by name family: OVR `viseme_*`, Rocketbox /
//   VALID `h_expressions.*` (with their `h_teeth.t_*` teeth morphs following
//   the face morph of the same name), ARKit's 52 (`jawOpen`, `mouthFunnel`,
//   `eyeBlinkLeft`, `mouthSmile_L`, ...), and plain names (`Angry`,
//   `Surprised`, `Sad`, `blink`, `a i u e o`, ...);
// - VRM expressions: VRM 0.x blendShapeGroups presets (a i u e o, blink,
//   blink_l / blink_r, joy angry sorrow fun) and VRM 1.0 expressions
//   (aa ih ou ee oh, blink, blinkLeft / blinkRight, happy angry sad relaxed
//   surprised), applied by name by VRM runtimes (three-vrm, VMC receivers)
//   and resolved into their morph target binds for a GLB;
// - a jaw bone where the rig has one (the jaw role, or a joint named *jaw*
//   under the head), turned by jaw_open_deg about its hinge, the rest pose's
//   left-right axis square to the jaw bone.
// Each control's weight is clamp(Σ coefficient × input, 0, 1) over the
// inputs of FaceInput; mouth-opening controls are scaled by (1 − PP) so that
// B/P/M close the lips where the rig can. The vowel inputs (aa E ih oh ou)
// are the viseme's weight times how far the jaw is open, relative to the
// speaker's wide speech opening (face::kSmplxJawSpeechWideDeg), so a vowel's
// mouth opens as wide as the speech's jaw does (after JALI, Edwards et al.,
// SIGGRAPH 2016: jaw and lips scale the visemes), not fully on every
// syllable. One mouth family drives the mouth
// (the richest the rig has: OVR > Rocketbox > ARKit > VRM vowels > plain
// vowels); eyes, brows and expressions come from every family; a morph a
// driven VRM expression binds is not driven again on its own. A map file
// (JSON, FaceMapOptions) overrides any of it.
//
// Users: the GLB writer (MorphWeights per frame, ApplyJaw), the studio
// (controls() once: mesh + morph names or VRM expression names; Weights()
// per frame), VMC (the VRM expressions' vmc_name and Weights()).
// Plain C++; no gRPC.
#pragma once

#include <Eigen/Core>
#include <array>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/face/face_frame.h"
#include "common/face/jaw.h"
#include "common/motion/skeleton.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::retarget {

// The rig-neutral inputs, computed from a FaceFrame (FaceInputs).
enum FaceInput : int {
  // The 15 OVR viseme weights: kInputOvrFirst + face::OvrViseme; the vowels
  // (aa E ih oh ou) times clamp(jaw_open_deg / vowel_open_deg, 0, 1).
  kInputOvrFirst = 0,
  kInputJaw = face::kNumOvrVisemes,  // jaw_open_deg / kJawFullOpenDeg, clamped to 0..1
  kInputBlinkLeft,
  kInputBlinkRight,
  kInputBrowRaise,
  kInputHappy,      // expression_weight while the expression is happy, else 0
  kInputAngry,
  kInputSad,
  kInputSurprised,
  kNumFaceInputs
};
// The vowel visemes, whose inputs FaceInputs opens with the jaw.
inline constexpr std::array<face::OvrViseme, 5> kVowelVisemes = {
    face::OvrViseme::kAA, face::OvrViseme::kE, face::OvrViseme::kIH, face::OvrViseme::kOH, face::OvrViseme::kOU};

// A jaw opened this far is a fully open mouth shape (weight 1), unless a map
// file says otherwise (jaw_full_open_deg).
inline constexpr double kJawFullOpenDeg = 25.0;

// "sil" .. "ou" (the OVR names), "jaw", "blink_left", "blink_right",
// "brow_raise", "happy", "angry", "sad", "surprised": the names map files use.
std::string_view FaceInputName(int input);
std::optional<int> ParseFaceInput(std::string_view name);
// The inputs of one frame (values in 0..1). vowel_open_deg 0, or a frame
// whose jaw is unknown (FaceFrame::jaw_known), leaves the vowels at their
// weights.
void FaceInputs(const face::FaceFrame& frame, std::span<float, kNumFaceInputs> out,
                double jaw_full_open_deg = kJawFullOpenDeg,
                double vowel_open_deg = face::kSmplxJawSpeechWideDeg);

enum class FaceControlKind { kMorphTarget, kVrmExpression };

struct FaceTerm {
  int input = 0;
  float coefficient = 0;
};

// One of the rig's face controls and how it is driven.
struct FaceControl {
  FaceControlKind kind = FaceControlKind::kMorphTarget;
  // The morph target's name (as the file names it), or the VRM expression's
  // (VRM 1.0: the preset key "aa" / custom name; VRM 0.x: the presetName
  // "a", "blink_l", "joy", or the group name of a custom one).
  std::string name;
  // Morph targets: the glTF mesh (its name and index) and the target's index.
  std::string mesh;
  int mesh_index = -1;
  int target = -1;
  // How it was recognised: "ovr", "rocketbox", "arkit", "names", "vrm0",
  // "vrm1", or "map" (the map file).
  std::string family;
  // "mouth", "eyes", "brows", "expression", "teeth" ("" when not driven).
  std::string group;
  // weight = clamp(Σ terms, 0, 1) [× (1 − PP) when closes_for_pp]; or, when
  // follows >= 0, the weight of controls()[follows].
  std::vector<FaceTerm> terms;
  bool closes_for_pp = false;
  int follows = -1;
  // VRM expressions: 0..1 weights become 0 or 1 (the file's isBinary).
  bool binary = false;
  // VRM expressions: the name a VMC receiver takes (/VMC/Ext/Blend/Val):
  // VRM 0.x "A" "I" "U" "E" "O" "Blink" "Blink_L" "Blink_R" "Joy" "Angry"
  // "Sorrow" "Fun" (custom: the group name), VRM 1.0 the expression name.
  std::string vmc_name;
  bool driven() const { return follows >= 0 || !terms.empty(); }
  // "aa 1 + E 0.3, x(1-PP)", "follows h_expressions.AE_AA_h", "not driven (...)".
  std::string why_not;  // set for controls recognised but left undriven
  std::string DrivenBy(const std::vector<FaceControl>& all) const;
};

struct JawBone {
  int joint = -1;  // rig joint, -1 = none
  std::string name;
  // Rest-pose (rig world) axis about which a positive angle opens the jaw.
  Eigen::Vector3d hinge_axis = Eigen::Vector3d::UnitX();
  double max_deg = 30;
  std::string found_by;  // "role" (VRM jaw, SMPL-X jaw), "name", "map"
};

// A glTF mesh some driven control moves: every one of its targets.
struct MorphMesh {
  int mesh = -1;
  std::string name;
  int num_targets = 0;
  std::vector<std::string> target_names;
  std::vector<int> nodes;  // the nodes that draw it (one weights channel each)
};

struct FaceMapOptions {
  // A map file's text (JSON, docs/retarget.md "Face map files"); empty: automatic.
  std::string map_json;
  std::string map_source = "face map";  // names it in errors
};

// The weight of one control for a frame's inputs (FaceInputs): its terms
// summed and clamped to 0..1, times 1 − PP when B/P/M close it, then 0 or 1
// for a binary one. FaceMap::Weights applies it to every control.
float ControlWeight(const FaceControl& control, std::span<const float, kNumFaceInputs> inputs);

// A VRM expression preset as FaceMap drives it on a VRM rig (terms, group,
// B/P/M gate; no family: the name alone may be either version's), without a rig:
// `name` is a VRM 0.x presetName ("a", "blink_l", "joy") or a VRM 1.0 name
// ("aa", "blinkLeft", "happy"). nullopt for a preset kinemo's face has no
// channel for (fun, relaxed, neutral, lookUp...) and for "blink" when
// `per_eye_blinks` (then blink_l / blink_r carry the eyes, as on a VRM whose
// blink_l and blink_r are bound). The VMC sender (common/vmc/blend.h) sends
// its mouth and expressions through this, so a VRM app over VMC shows the
// face a VRM file written by kinemo shows.
std::optional<FaceControl> VrmPresetControl(std::string_view name, bool per_eye_blinks);

class FaceMap {
 public:
  // The rig's morph targets and (for a VRM) expressions, and a jaw bone
  // (glTF rigs); for a BVH rig only the jaw. INVALID_ARGUMENT naming the map
  // file's key for a bad map, or the VRM part for a bad expression bind.
  static StatusOr<FaceMap> Create(const Rig& rig, const FaceMapOptions& options = {});

  // Every face control the rig offers (driven or not), in a fixed order:
  // VRM expressions first, then morph targets by mesh and index.
  const std::vector<FaceControl>& controls() const { return controls_; }
  int num_driven() const;
  const JawBone& jaw() const { return jaw_; }
  // The rig's family ("vrm0", "vrm1", "ovr", ...) that drives the mouth, "" for none.
  const std::string& mouth_family() const { return mouth_family_; }
  // The jaw opening that makes the `jaw` input 1 (kJawFullOpenDeg, or the map's).
  double jaw_full_open_deg() const { return jaw_full_open_deg_; }
  // The jaw opening at which a vowel shows at its full weight
  // (face::kSmplxJawSpeechWideDeg, or the map's vowel_open_deg; 0 = off).
  double vowel_open_deg() const { return vowel_open_deg_; }

  // Per control (controls().size()), the weight for `frame`. Allocation-free.
  void Weights(const face::FaceFrame& frame, std::span<float> weights) const;
  // The jaw's opening for `frame`, degrees (0 without a jaw bone).
  double JawAngleDeg(const face::FaceFrame& frame) const;
  // Sets the jaw joint's rotation channels in a frame on `skeleton` (the
  // rig's) to the opening `angle_deg` about the hinge. No-op without a jaw.
  Status ApplyJaw(const motion::Skeleton& skeleton, double angle_deg, std::span<double> frame) const;

  // The meshes whose morph targets driven controls move, and the weight of
  // every target of them from control weights (VRM expressions resolved
  // into their binds), concatenated in morph_meshes() order.
  const std::vector<MorphMesh>& morph_meshes() const { return morph_meshes_; }
  int num_morph_weights() const { return num_morph_weights_; }
  void MorphWeights(std::span<const float> control_weights, std::span<float> morph_weights) const;

 private:
  struct Bind {
    int control;
    int flat;  // index into the concatenated morph weights
    float weight;
  };
  std::vector<FaceControl> controls_;
  JawBone jaw_;
  std::string mouth_family_;
  double jaw_full_open_deg_ = kJawFullOpenDeg;
  double vowel_open_deg_ = face::kSmplxJawSpeechWideDeg;
  std::vector<MorphMesh> morph_meshes_;
  int num_morph_weights_ = 0;
  std::vector<Bind> binds_;
};

// A face track sampled on a clip's frames (frame f at f × frame_time_s):
// the weights of every control and every morph target, and the jaw angle,
// linearly interpolated between face frames (held at the ends).
struct FaceAnimation {
  int num_frames = 0;
  std::vector<float> control_weights;  // num_frames × controls
  std::vector<float> morph_weights;    // num_frames × num_morph_weights
  std::vector<double> jaw_deg;         // num_frames
};
StatusOr<FaceAnimation> SampleFace(const FaceMap& map, const face::FaceTrack& track, int num_frames,
                                   double frame_time_s);
// The jaw of `face` into a clip on the rig's skeleton (no-op without a jaw).
Status ApplyJawToClip(const FaceMap& map, const FaceAnimation& face, motion::Clip* clip);

}  // namespace kinemo::retarget
