// FBX characters in, through Debian's libassimp (assimp 5.2): the one place
// where kinemo reads FBX. The file becomes a glTF document in memory (a
// GltfSource), so that every reader of a character (retarget, animate
// --rig, rig info, the planner's rigs, the studio) takes FBX rigs the way it
// takes GLB ones, and a retargeted FBX rig is written as a GLB.
//
// What the document holds:
// - one node per FBX node, same names and hierarchy, in metres and y-up:
//   the file's unit (GlobalSettings UnitScaleFactor, centimetres per unit:
//   1 for Blender's and Mixamo's exports) is baked into every translation and
//   vertex, its axes (UpAxis, FrontAxis, CoordAxis) turned into glTF's
//   (y up, z front, x right) at the root;
// - one skin: the bones (FBX clusters) and the nodes between them; their
//   inverse bind matrices from the clusters' bind pose (which may differ
//   from the nodes' default pose). A file without meshes (a skeleton alone)
//   is a skin of all its nodes but the root, the "...end" leaves and the
//   mesh nodes, at their default pose;
// - the skinned meshes (optional), vertices at the bind pose in world
//   space, one glTF mesh per assimp mesh (FBX meshes are split by
//   material), up to four weights per vertex, blend shapes as morph
//   targets named in extras.targetNames, materials as base colours only
//   (textures are not carried over).
// Every size is bounded (FbxLimits) and assimp's own structure check runs;
// refusals are INVALID_ARGUMENT naming the file and the part:
//   "man.fbx: not an FBX file (no \"Kaydara FBX Binary\" header, no FBXHeaderExtension)"
//   "man.fbx: FBX: <assimp's message>"
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "common/motion/skeleton.h"
#include "common/retarget/gltf.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::retarget {

struct FbxLimits {
  std::uint64_t max_bytes = std::uint64_t{512} << 20;  // the file
  std::uint32_t max_nodes = 65536;
  std::uint32_t max_bones = 4096;                      // skin joints
  std::uint64_t max_vertices = std::uint64_t{1} << 24; // over all meshes, morph targets included
  std::uint32_t max_meshes = 4096;
};

// Reads a binary or ASCII FBX file (see above). NOT_FOUND for a missing
// file. src->format is "fbx"; src->source_meters_per_unit the file's unit.
StatusOr<std::shared_ptr<GltfSource>> ReadFbx(const std::string& path, const FbxLimits& limits = {});

// The same for bytes held in memory; `name` stands for the path in errors.
StatusOr<std::shared_ptr<GltfSource>> ReadFbxFromMemory(std::string_view bytes, const std::string& name,
                                                        const FbxLimits& limits = {});

// Writes an FBX rig's character (rig.gltf->format "fbx", read from a file)
// with `clip` (a clip on rig.skeleton) as its one animation, "kinemo",
// through assimp's FBX exporter (binary FBX 7.4): the source file is read
// again, every joint's node gets a rotation key per frame (and the hips
// their translation), in the file's own units and axes; the meshes are
// written as assimp read them (split by material, textures not carried
// over). FAILED_PRECONDITION for a rig that is not an FBX file's.
Status WriteAnimatedFbx(const Rig& rig, const motion::Clip& clip, const std::string& path);

// Whether `path` names an FBX file (its extension, any case).
bool IsFbxPath(std::string_view path);

}  // namespace kinemo::retarget
