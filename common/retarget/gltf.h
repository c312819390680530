// glTF 2.0 / GLB input and output for retargeting, through tinygltf
// (Debian's libtinygltf-dev). Reading keeps the whole document so that the
// character (meshes, skins, materials, textures) is written back unchanged
// with the retargeted motion added as a glTF animation.
#pragma once

#include <tiny_gltf.h>

#include <string>

#include "common/motion/skeleton.h"
#include "common/retarget/rig.h"
#include "common/status/status.h"

namespace kinemo::retarget {

struct GltfSource {
  std::string path;
  tinygltf::Model model;
};

// Parses a .glb or .gltf file (images are kept as they are, not decoded).
StatusOr<std::shared_ptr<GltfSource>> ReadGltf(const std::string& path);

struct GlbWriteOptions {
  std::string animation_name = "kinemo";
  // Keep the animations the file already has (after the new one).
  bool keep_animations = true;
};

// Writes `rig`'s character (rig.gltf must be set) as a GLB with `clip` (a
// clip on rig.skeleton, e.g. Retargeter output) as its first animation:
// a rotation channel per joint node, a translation channel for joints with
// position channels (the hips). Joint nodes' default translations are set
// to their bind-pose values.
Status WriteAnimatedGlb(const Rig& rig, const motion::Clip& clip, const std::string& path,
                        const GlbWriteOptions& options = {});

}  // namespace kinemo::retarget
