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

// A VRM Animation of BEAT2 motion on Godette (VRM 0.x): the humanoid under
// VRM 1.0 names (her thumbs' Proximal is 1.0's Metacarpal), no mesh, rest
// rotations identity, the model turned to face +Z (her left hand on +x, as
// VRM 1.0 has it), the hips keyed in metres; refused for a rig that is no VRM.
TEST(Vrma, GodetteHumanoidUnderVrm1NamesFacingPlusZ) {
  auto clip = motion::ReadBvhFile(Data("paired/beat2/2_scott_0_1_1.bvh"));
  ASSERT_TRUE(clip.ok());
  clip->frames.conservativeResize(30, clip->frames.cols());
  auto rig = LoadGltfRig(Data("characters/godette.vrm"));
  ASSERT_TRUE(rig.ok()) << rig.status();
  auto out = RetargetClip(*clip, 0.01, *rig);
  ASSERT_TRUE(out.ok()) << out.status();
  const std::string path = (std::filesystem::path(testing::TempDir()) / "out.vrma").string();
  ASSERT_TRUE(WriteVrmAnimation(*rig, out->clip, path).ok());
  auto back = ReadGltf(path);
  ASSERT_TRUE(back.ok()) << back.status();
  const tinygltf::Model& m = (*back)->model;
  EXPECT_TRUE(m.meshes.empty());
  ASSERT_EQ(m.animations.size(), 1u);
  const tinygltf::Value& bones = Member(Member(m.extensions.at("VRMC_vrm_animation"), "humanoid"), "humanBones");
  ASSERT_TRUE(bones.IsObject());
  auto node_of = [&](const std::string& bone) { return Member(Member(bones, bone), "node").GetNumberAsInt(); };
  for (const char* bone : {"hips", "spine", "head", "leftUpperArm", "rightHand", "leftThumbMetacarpal",
                           "leftThumbProximal", "leftThumbDistal", "rightLittleDistal", "leftToes"}) {
    EXPECT_TRUE(Member(bones, bone).IsObject()) << bone;
  }
  EXPECT_FALSE(Member(bones, "leftThumbIntermediate").IsObject());  // VRM 0.x's name
  EXPECT_EQ(m.nodes[static_cast<size_t>(node_of("leftThumbMetacarpal"))].name, "leftThumbMetacarpal");
  for (const tinygltf::Node& n : m.nodes) EXPECT_TRUE(n.rotation.empty()) << n.name;
  // Facing +Z: the left hand's rest is on +x, the hips' about 0.65 m up.
  double left_x = 0;
  for (int n = node_of("leftHand"); n >= 0;) {
    left_x += m.nodes[static_cast<size_t>(n)].translation[0];
    int parent = -1;
    for (size_t p = 0; p < m.nodes.size(); ++p) {
      for (int c : m.nodes[p].children) parent = c == n ? static_cast<int>(p) : parent;
    }
    n = parent;
  }
  EXPECT_GT(left_x, 0.3);
  EXPECT_NEAR(m.nodes[static_cast<size_t>(node_of("hips"))].translation[1], 0.65, 0.05);
  // Keys: 30 per bone; the hips' translation among them.
  int translations = 0;
  for (const auto& ch : m.animations[0].channels) {
    EXPECT_EQ(m.accessors[static_cast<size_t>(m.animations[0].samplers[static_cast<size_t>(ch.sampler)].input)].count, 30u);
    translations += ch.target_path == "translation";
    if (ch.target_path == "translation") {
      EXPECT_EQ(ch.target_node, node_of("hips"));
    }
  }
  EXPECT_EQ(translations, 1);
  // A GLB that is no VRM: refused, naming it.
  auto man = LoadGltfRig(Data("characters/quaternius_man_casual.glb"));
  ASSERT_TRUE(man.ok());
  auto on_man = RetargetClip(*clip, 0.01, *man);
  ASSERT_TRUE(on_man.ok());
  const Status refused = WriteVrmAnimation(*man, on_man->clip, path + "2");
  EXPECT_EQ(refused.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("not a VRM"), std::string::npos) << refused;
  EXPECT_FALSE(std::filesystem::exists(path + "2"));
}

}  // namespace
}  // namespace kinemo::retarget
