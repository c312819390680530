// GLB output: the written file, read back, plays the retargeted motion: its
// animation's node transforms put the hands where the clip does.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <map>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/retarget/gltf.h"
#include "common/retarget/retarget.h"
#include "common/retarget/transform.h"
#include "tests/unit/retarget/test_data.h"

namespace kinemo::retarget {
namespace {

using namespace roles;

using test::Data;

std::vector<float> ReadFloats(const tinygltf::Model& m, int accessor) {
  const tinygltf::Accessor& a = m.accessors[accessor];
  const tinygltf::BufferView& v = m.bufferViews[a.bufferView];
  const int comps = tinygltf::GetNumComponentsInType(a.type);
  std::vector<float> out(a.count * comps);
  std::memcpy(out.data(), m.buffers[v.buffer].data.data() + v.byteOffset + a.byteOffset, out.size() * sizeof(float));
  return out;
}

TEST(Glb, WrittenAnimationReproducesTheClip) {
  auto clip = motion::ReadBvhFile(Data("paired/beat2/2_scott_0_1_1.bvh"));
  ASSERT_TRUE(clip.ok());
  clip->frames.conservativeResize(90, clip->frames.cols());
  for (const char* character : {"characters/quaternius_man_casual.glb", "characters/robot_expressive.glb"}) {
    auto rig = LoadGltfRig(Data(character));
    ASSERT_TRUE(rig.ok()) << rig.status();
    auto out = RetargetClip(*clip, 0.01, *rig);
    ASSERT_TRUE(out.ok()) << out.status();
    const std::string path = (std::filesystem::path(testing::TempDir()) / "out.glb").string();
    ASSERT_TRUE(WriteAnimatedGlb(*rig, out->clip, path).ok());

    auto back = ReadGltf(path);
    ASSERT_TRUE(back.ok()) << back.status();
    tinygltf::Model& m = (*back)->model;
    const size_t before = rig->gltf->model.animations.size();
    ASSERT_EQ(m.animations.size(), before + 1) << character;
    const tinygltf::Animation& anim = m.animations[0];
    EXPECT_EQ(anim.name, "kinemo");
    EXPECT_EQ(m.meshes.size(), rig->gltf->model.meshes.size());
    // Apply frame f of the animation to the nodes, then compare world positions.
    for (int f : {0, 45, 89}) {
      for (const auto& ch : anim.channels) {
        const std::vector<float> v = ReadFloats(m, anim.samplers[ch.sampler].output);
        tinygltf::Node& node = m.nodes[ch.target_node];
        if (ch.target_path == "rotation") {
          node.rotation = {v[4 * f], v[4 * f + 1], v[4 * f + 2], v[4 * f + 3]};
        } else if (ch.target_path == "translation") {
          node.translation = {v[3 * f], v[3 * f + 1], v[3 * f + 2]};
        }
      }
      auto tree = BuildNodeTree(m);
      ASSERT_TRUE(tree.ok());
      auto pose = motion::ComputeWorldPose(out->clip, f);
      ASSERT_TRUE(pose.ok());
      for (Role r : {Side(0, kForearm), Side(1, kForearm), Side(0, kShin), kHead}) {
        const int j = rig->roles.joint[r];
        const Eigen::Vector3d from_glb = tree->global[rig->node[j]].block<3, 1>(0, 3);
        EXPECT_LT((from_glb - pose->positions[j]).norm(), 2e-3)
            << character << " frame " << f << " " << RoleName(r) << ": " << from_glb.transpose() << " vs "
            << pose->positions[j].transpose();
      }
    }
  }
}

}  // namespace
}  // namespace kinemo::retarget
