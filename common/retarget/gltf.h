// glTF 2.0 / GLB input and output for retargeting, through tinygltf
// (Debian's libtinygltf-dev). Reading keeps the whole document so that the
// character (meshes, skins, materials, textures) is written back unchanged
// with the retargeted motion added as a glTF animation.
#pragma once

#include <tiny_gltf.h>

#include <Eigen/Core>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/motion/skeleton.h"
#include "common/retarget/face_map.h"
#include "common/retarget/gltf_decode.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::retarget {

struct GltfSource {
  std::string path;
  // A plain document: compressed buffer views and primitives are decoded on
  // reading (gltf_decode.h), so readers see ordinary accessors.
  tinygltf::Model model;
  // The compression extensions the file used and reading decoded
  // ("EXT_meshopt_compression", "KHR_draco_mesh_compression").
  std::vector<std::string> decoded;
  // "fbx" for a document made from an FBX file (fbx.h), else empty; the
  // FBX file's unit in metres (the document itself is in metres).
  std::string format;
  double source_meters_per_unit = 1;
};

// Parses a .glb or .gltf file (images are kept as they are, not decoded).
// EXT_meshopt_compression and KHR_draco_mesh_compression are decoded
// (gltf_decode.h); KHR_mesh_quantization accessors are read as they are.
// A .fbx file is read through assimp into a glTF document (fbx.h).
StatusOr<std::shared_ptr<GltfSource>> ReadGltf(const std::string& path);

// Parses a GLB held in memory (an upload); `name` stands for the path in
// errors ("character.glb: not a valid glTF/GLB: ..."). Decodes as ReadGltf.
StatusOr<std::shared_ptr<GltfSource>> ReadGlbFromMemory(std::string_view bytes, const std::string& name,
                                                        const GltfDecodeLimits& limits = {});

// The glTF node transforms of a pose on a glTF rig: for every joint its
// node's local rotation, and for the joints with position channels (the
// hips, the topmost joint) its node's local translation, both relative to
// the parent node as the file's node tree has it. Joint nodes sit at their
// bind-pose local translation (bind_translation()), which differs from the
// node default for rigs whose default pose is not the bind pose. Used by
// the GLB writer and by the studio, which sends these to the page to skin.
class NodePoser {
 public:
  // `rig` must be a glTF rig (rig.gltf set).
  static StatusOr<NodePoser> Create(const Rig& rig);

  // Per joint (rig order): the bind-pose local translation of its node.
  const std::vector<Eigen::Vector3d>& bind_translation() const { return bind_translation_; }
  // The joints with position channels, in order: their translations come
  // with every pose.
  const std::vector<int>& translated_joints() const { return translated_; }

  // `frame`: channel values on rig.skeleton. `rotations` receives x y z w
  // per joint (4 × joints), `translations` x y z per translated joint.
  // Allocation-free.
  Status Pose(std::span<const double> frame, std::span<float> rotations, std::span<float> translations);

 private:
  struct Frame3 {
    Eigen::Matrix3d r;
    Eigen::Vector3d p;
    double s;
  };
  Frame3 ParentOf(int j) const;  // from pos_, rot_

  motion::Skeleton skeleton_;
  std::vector<Eigen::Matrix3d> bind_rotation_;
  std::vector<int> parent_joint_;             // per joint: joint of the parent node, or -1
  std::vector<Frame3> fixed_parent_;          // per joint: the parent node's default transform when no joint
  std::vector<double> bind_scale_;
  std::vector<Eigen::Vector3d> bind_translation_;
  std::vector<int> translated_;
  std::vector<Eigen::Vector3d> pos_;
  std::vector<Eigen::Matrix3d> rot_;
};

struct GlbWriteOptions {
  std::string animation_name = "kinemo";
  // Keep the animations the file already has (after the new one).
  bool keep_animations = true;
  // WebP textures (EXT_texture_webp) without a fallback get a PNG copy as
  // their glTF source, the WebP staying as the extension's source: readers
  // without WebP (Blender 3.x) open the file. False: WebP only.
  bool png_fallbacks = true;
  // The face (face_map.h), both or neither: a `weights` channel per node of
  // every mesh in face_map->morph_meshes(), its sampler output holding every
  // morph target of the mesh per frame (as glTF requires), from
  // face->morph_weights (face->num_frames must be the clip's). The jaw is
  // the clip's own (ApplyJawToClip before writing).
  const FaceMap* face_map = nullptr;
  const FaceAnimation* face = nullptr;
};

// Writes `rig`'s character (rig.gltf must be set) as a GLB with `clip` (a
// clip on rig.skeleton, e.g. Retargeter output) as its first animation:
// a rotation channel per joint node, a translation channel for joints with
// position channels (the hips), and the face's morph weights when
// options.face is set. Joint nodes' default translations are set to their
// bind-pose values. A compressed input is written decoded (plain buffer
// views, no EXT_meshopt_compression / KHR_draco_mesh_compression), so that
// any glTF reader takes it; KHR_mesh_quantization and image formats such as
// EXT_texture_webp stay as the input had them.
Status WriteAnimatedGlb(const Rig& rig, const motion::Clip& clip, const std::string& path,
                        const GlbWriteOptions& options = {});

struct VrmaWriteOptions {
  std::string animation_name = "kinemo";
  // The face (face_map.h), both or neither: the rig's driven VRM
  // expressions, each as an expression node whose translation x is its
  // weight per frame (VRMC_vrm_animation). VRM 0.x presets are written under
  // their VRM 1.0 names (a -> aa, i -> ih, u -> ou, e -> ee, o -> oh,
  // blink_l -> blinkLeft, blink_r -> blinkRight, joy -> happy, sorrow ->
  // sad, fun -> relaxed); other driven expressions as custom ones.
  const FaceMap* face_map = nullptr;
  const FaceAnimation* face = nullptr;
};

// Writes `clip` (on `rig.skeleton`, e.g. Retargeter output; a VRM rig,
// 0.x or 1.0) as a VRM Animation: a GLB with the VRMC_vrm_animation 1.0
// extension, which VRM runtimes (UniVRM, three-vrm's three-vrm-animation)
// play on any VRM character. It holds no mesh: one node per humanoid bone
// the rig maps, named and keyed by its VRM 1.0 bone name (VRM 0.x thumbs
// Proximal / Intermediate / Distal become Metacarpal / Proximal / Distal),
// parented bone to bone, at rest in the rig's T-pose with identity rotations
// (the form the specification's "normalized" pose data takes), in metres,
// facing +Z (VRM 1.0's model space: a VRM 0.x rig, which faces -Z, is turned
// half a turn about y). Per frame: each bone's rotation relative to its
// parent bone, the hips' translation, and the face's expression weights.
// INVALID_ARGUMENT for a rig that is not a VRM or has no hips.
Status WriteVrmAnimation(const Rig& rig, const motion::Clip& clip, const std::string& path,
                         const VrmaWriteOptions& options = {});

// A VRM Animation read as motion (ReadVrmAnimation).
struct VrmAnimationClip {
  // One joint per humanoid bone kinemo has a role for, named by its VRM 1.0
  // name, parented bone to bone, offsets from the file's T-pose (metres,
  // facing +Z); Z X Y rotation channels, position channels on the hips. Each
  // frame's rotations are the bones' turns from that T-pose, so the clip is a
  // BVH of the file's motion.
  motion::Clip clip;
  // The role map of that skeleton ({"hips": "hips", "left_upper_arm":
  // "leftUpperArm", ...}) for RoleMapChoice.map_json.
  std::string role_map_json;
};
// Frames ReadVrmAnimation gives at most (2 hours at 30 fps).
inline constexpr int kMaxVrmaFrames = 216000;

// Reads a VRM Animation (.vrma, VRMC_vrm_animation): its first animation's
// humanoid motion sampled at `fps` (0: the keys' own rate, the median key
// spacing of the longest track, 30 when it has none) from 0 to its last key (rotations
// spherically, translations linearly; STEP keys held; a CUBICSPLINE read
// through its values). Expressions and lookAt are not read. INVALID_ARGUMENT
// naming the part for a file without the extension, hips or consistent
// keys; NOT_FOUND for a missing file.
StatusOr<VrmAnimationClip> ReadVrmAnimation(const std::string& path, double fps = 0);

// `clip` on `rig` written with its face (both or neither null): a VRM
// Animation when `vrma` (WriteVrmAnimation), else the character's GLB
// (WriteAnimatedGlb). What `kinemo retarget -o OUT.glb|OUT.vrma` and the
// studio's export write.
Status WriteCharacterAnimation(const Rig& rig, const motion::Clip& clip, const std::string& path, bool vrma,
                               const FaceMap* face_map, const FaceAnimation* face);

// The VRM 1.0 humanoid bone name of a role ("hips", "upperChest",
// "leftUpperArm", "leftThumbMetacarpal"); "" for none.
std::string_view VrmHumanBoneName(Role role);

}  // namespace kinemo::retarget
