// GLB output: the written file, read back, plays the retargeted motion: its
// animation's node transforms put the hands where the clip does. VRM
// Animations: what is written for Godette, and read back.
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

// A VRM Animation read back (ReadVrmAnimation) is the motion that was
// written: BEAT2 on Godette, written, read at the same rate, puts the hands,
// feet and head where the clip on Godette has them (turned to face +Z).
TEST(Vrma, ReadBackGivesTheWrittenMotion) {
  auto clip = motion::ReadBvhFile(Data("paired/beat2/2_scott_0_2_2.bvh"));
  ASSERT_TRUE(clip.ok());
  clip->frames.conservativeResize(90, clip->frames.cols());
  auto rig = LoadGltfRig(Data("characters/godette.vrm"));
  ASSERT_TRUE(rig.ok()) << rig.status();
  auto out = RetargetClip(*clip, 0.01, *rig);
  ASSERT_TRUE(out.ok()) << out.status();
  const std::string path = (std::filesystem::path(testing::TempDir()) / "back.vrma").string();
  ASSERT_TRUE(WriteVrmAnimation(*rig, out->clip, path).ok());
  auto back = ReadVrmAnimation(path, 1.0 / out->clip.frame_time_s);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->clip.num_frames(), 90);
  EXPECT_EQ(back->clip.skeleton.num_joints(), 45);
  EXPECT_NE(back->role_map_json.find("\"left_thumb1\":\"leftThumbMetacarpal\""), std::string::npos) << back->role_map_json;
  const Eigen::Vector3d flip(-1, 1, -1);  // Godette (VRM 0.x) faces -Z
  for (int f : {0, 44, 89}) {
    auto written = motion::ComputeWorldPose(out->clip, f);
    auto read = motion::ComputeWorldPose(back->clip, f);
    ASSERT_TRUE(written.ok() && read.ok());
    for (const char* bone : {"leftHand", "rightHand", "leftFoot", "rightFoot", "head"}) {
      const int b = back->clip.skeleton.FindJoint(bone);
      ASSERT_GE(b, 0) << bone;
      const Role role = [&] {
        for (Role r = 0; r < kNumRoles; ++r) {
          if (VrmHumanBoneName(r) == bone) return r;
        }
        return Role{-1};
      }();
      const int j = rig->roles.joint[static_cast<size_t>(role)];
      const Eigen::Vector3d want = flip.cwiseProduct(written->positions[static_cast<size_t>(j)]) * rig->meters_per_unit;
      EXPECT_LT((read->positions[static_cast<size_t>(b)] - want).norm(), 1e-3)
          << bone << " frame " << f << ": " << read->positions[static_cast<size_t>(b)].transpose() << " vs "
          << want.transpose();
    }
  }
  // The same motion over another rest (VRM 1.0 allows rest rotations): the
  // left upper arm rests turned by Q, its keys turned to match (l -> l Q,
  // below it Q^-1 l Q, rest offsets Q^-1 t). The motion read is the same.
  auto src = ReadGltf(path);
  ASSERT_TRUE(src.ok());
  tinygltf::Model m = (*src)->model;
  const tinygltf::Value& bones = Member(Member(m.extensions.at("VRMC_vrm_animation"), "humanoid"), "humanBones");
  const int arm = Member(Member(bones, "leftUpperArm"), "node").GetNumberAsInt();
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, 0.5, 0.8).normalized()));
  m.nodes[static_cast<size_t>(arm)].rotation = {q.x(), q.y(), q.z(), q.w()};
  std::vector<int> below;
  for (std::vector<int> todo = m.nodes[static_cast<size_t>(arm)].children; !todo.empty();) {
    const int n = todo.back();
    todo.pop_back();
    below.push_back(n);
    for (int c : m.nodes[static_cast<size_t>(n)].children) todo.push_back(c);
  }
  for (int n : below) {
    auto& t = m.nodes[static_cast<size_t>(n)].translation;
    const Eigen::Vector3d v = q.conjugate() * Eigen::Vector3d(t[0], t[1], t[2]);
    t = {v.x(), v.y(), v.z()};
  }
  for (const auto& ch : m.animations[0].channels) {
    const bool is_arm = ch.target_node == arm;
    if (ch.target_path != "rotation" || (!is_arm && std::find(below.begin(), below.end(), ch.target_node) == below.end())) {
      continue;
    }
    const tinygltf::Accessor& a = m.accessors[static_cast<size_t>(m.animations[0].samplers[static_cast<size_t>(ch.sampler)].output)];
    const tinygltf::BufferView& v = m.bufferViews[static_cast<size_t>(a.bufferView)];
    float* keys = reinterpret_cast<float*>(m.buffers[0].data.data() + v.byteOffset + a.byteOffset);
    for (size_t k = 0; k < a.count; ++k) {
      const Eigen::Quaterniond l(keys[4 * k + 3], keys[4 * k], keys[4 * k + 1], keys[4 * k + 2]);
      const Eigen::Quaterniond turned = is_arm ? l * q : q.conjugate() * l * q;
      keys[4 * k] = static_cast<float>(turned.x());
      keys[4 * k + 1] = static_cast<float>(turned.y());
      keys[4 * k + 2] = static_cast<float>(turned.z());
      keys[4 * k + 3] = static_cast<float>(turned.w());
    }
  }
  const std::string rested = (std::filesystem::path(testing::TempDir()) / "rested.vrma").string();
  tinygltf::TinyGLTF writer;
  ASSERT_TRUE(writer.WriteGltfSceneToFile(&m, rested, true, true, false, true));
  auto again = ReadVrmAnimation(rested);
  ASSERT_TRUE(again.ok()) << again.status();
  ASSERT_EQ(again->clip.num_frames(), 90);
  for (int f : {0, 44, 89}) {
    auto a = motion::ComputeWorldPose(back->clip, f);
    auto b = motion::ComputeWorldPose(again->clip, f);
    ASSERT_TRUE(a.ok() && b.ok());
    for (const char* bone : {"leftHand", "leftLowerArm", "rightHand", "head"}) {
      const int j = back->clip.skeleton.FindJoint(bone);
      EXPECT_LT((a->positions[static_cast<size_t>(j)] - b->positions[static_cast<size_t>(again->clip.skeleton.FindJoint(bone))]).norm(),
                1e-4)
          << bone << " frame " << f;
    }
  }
  // Not a VRM Animation: named.
  const std::string glb = (std::filesystem::path(testing::TempDir()) / "plain.glb").string();
  ASSERT_TRUE(WriteAnimatedGlb(*rig, out->clip, glb).ok());
  auto refused = ReadVrmAnimation(glb);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("not a VRM Animation"), std::string::npos) << refused.status();
}

}  // namespace
}  // namespace kinemo::retarget
