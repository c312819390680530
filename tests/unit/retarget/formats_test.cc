// Character formats on real files (tests/data/characters): compressed glTF
// (EXT_meshopt_compression + KHR_mesh_quantization + EXT_texture_webp, the
// VALID avatars as gltfpack wrote them), VRM 0.x (Godette) and VRM 1.0 (the
// VRM consortium's expressions test model, a humanoid without a skin):
// decoding, rigs in metres, hostile inputs refused with the part named,
// retargeting quality on the VRM 1.0 humanoid.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/motion/bvh.h"
#include "common/motion/motion_check.h"
#include "common/retarget/gltf.h"
#include "common/retarget/gltf_decode.h"
#include "common/retarget/measures.h"
#include "common/retarget/mesh.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"
#include "common/retarget/rig_info.h"
#include "common/retarget/roles.h"
#include "tests/unit/retarget/test_data.h"

namespace kinemo::retarget {
namespace {

using test::Data;

const char* kValidMan = "characters/valid_white_m_1_casual.glb";
const char* kValidWoman = "characters/valid_aian_f_1_casual.glb";
const char* kGodette = "characters/godette.vrm";
const char* kVrm1 = "characters/formats/vrm1_expressions_test.vrm";

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The GLB's JSON chunk and the rest, to write damaged copies.
struct Glb {
  nlohmann::json json;
  std::string bin;  // the BIN chunk's bytes
};
Glb Split(const std::string& bytes) {
  std::uint32_t json_len;
  std::memcpy(&json_len, bytes.data() + 12, 4);
  Glb g;
  g.json = nlohmann::json::parse(bytes.substr(20, json_len));
  const size_t at = 20 + json_len;
  std::uint32_t bin_len;
  std::memcpy(&bin_len, bytes.data() + at, 4);
  g.bin = bytes.substr(at + 8, bin_len);
  return g;
}
std::string Join(const Glb& g) {
  std::string text = g.json.dump();
  while (text.size() % 4) text += ' ';
  std::string out = "glTF";
  auto put = [&](std::uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
  put(2);
  put(static_cast<std::uint32_t>(12 + 8 + text.size() + 8 + g.bin.size()));
  put(static_cast<std::uint32_t>(text.size()));
  put(0x4E4F534A);
  out += text;
  put(static_cast<std::uint32_t>(g.bin.size()));
  put(0x004E4942);
  out += g.bin;
  return out;
}

TEST(CompressedGltf, ValidAvatarsLoadInMetres) {
  for (const char* file : {kValidMan, kValidWoman}) {
    auto src = ReadGltf(Data(file));
    ASSERT_TRUE(src.ok()) << file << ": " << src.status();
    EXPECT_EQ((*src)->decoded, std::vector<std::string>{"EXT_meshopt_compression"}) << file;
    auto rig = RigFromGltf(*src);
    ASSERT_TRUE(rig.ok()) << file << ": " << rig.status();
    EXPECT_EQ(rig->roles.family, RigFamily::kMixamo);
    // Adults: legs 0.8-0.95 m, hips about 0.95-1.05 m above the floor. (The
    // skeleton came out 1/100 of this size while the quantization's
    // dequantization folded into the inverse bind matrices was ignored.)
    const double leg = rig->LegLength() * rig->meters_per_unit;
    EXPECT_GT(leg, 0.75) << file;
    EXPECT_LT(leg, 1.0) << file;
    EXPECT_GT(rig->HipsHeight(), 0.85) << file;
    EXPECT_LT(rig->HipsHeight(), 1.1) << file;
    // The skinned mesh decodes: quantized positions (normalized shorts),
    // normals (normalized bytes), and the skin weights.
    auto mesh = LoadCharacterMesh(*rig);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    EXPECT_GT(mesh->triangles.size(), 50000u) << file;
    const Eigen::Vector3f size = mesh->max_corner - mesh->min_corner;
    std::printf("[valid] %s: %zu triangles, bind-pose box %.2f x %.2f x %.2f m (leg %.3f m)\n", file,
                mesh->triangles.size(), size.x(), size.y(), size.z(), leg);
  }
}

// The same character compressed by another tool (glTF-Transform 4.5.1 with
// Google's Draco encoder, and with meshoptimizer after quantization:
// formats/make_compressed.mjs): the same rig and the same mesh as the plain
// file, to the codecs' precision.
TEST(CompressedGltf, DracoAndMeshoptCopiesAreTheSameCharacter) {
  auto plain = LoadGltfRig(Data("characters/quaternius_man_casual.glb"));
  ASSERT_TRUE(plain.ok());
  auto plain_mesh = LoadCharacterMesh(*plain);
  ASSERT_TRUE(plain_mesh.ok());
  for (const auto& [file, ext] : std::vector<std::pair<std::string, std::string>>{
           {"characters/formats/quaternius_man_draco.glb", "KHR_draco_mesh_compression"},
           {"characters/formats/quaternius_man_meshopt.glb", "EXT_meshopt_compression"}}) {
    auto src = ReadGltf(Data(file));
    ASSERT_TRUE(src.ok()) << file << ": " << src.status();
    EXPECT_EQ((*src)->decoded, std::vector<std::string>{ext});
    auto rig = RigFromGltf(*src);
    ASSERT_TRUE(rig.ok()) << file << ": " << rig.status();
    ASSERT_EQ(rig->skeleton.num_joints(), plain->skeleton.num_joints()) << file;
    const auto a = plain->RestPositions(), b = rig->RestPositions();
    double worst = 0;
    for (size_t j = 0; j < a.size(); ++j) worst = std::max(worst, (a[j] - b[j]).norm());
    EXPECT_LT(worst, 1e-4) << file << ": rest positions, metres";
    auto mesh = LoadCharacterMesh(*rig);
    ASSERT_TRUE(mesh.ok()) << file << ": " << mesh.status();
    EXPECT_EQ(mesh->triangles.size(), plain_mesh->triangles.size()) << file;
    EXPECT_LT((mesh->min_corner - plain_mesh->min_corner).norm(), 2e-3) << file;
    EXPECT_LT((mesh->max_corner - plain_mesh->max_corner).norm(), 2e-3) << file;
    std::printf("[compressed] %s: rest positions within %.2g m, bounds %.4f / %.4f m apart\n", file.c_str(), worst,
                (mesh->min_corner - plain_mesh->min_corner).norm(), (mesh->max_corner - plain_mesh->max_corner).norm());
  }
}

// The page (and the GLB) poses the VALID man by node transforms: joint nodes
// at their bind translation, in their parents' scaled spaces (its Hips and
// mesh nodes carry scale 0.01). The file's default pose is its bind pose, so
// the bind translations are the nodes' own, and the hips stand ~1 m high.
// (With the bind space taken as the mesh node's world the hips came out at
// 0.0016 m and the Spine's bind translation at -0.045 against its -4.34 cm.)
TEST(CompressedGltf, ValidNodeTransformsAreItsOwn) {
  auto man = LoadGltfRig(Data(kValidMan));
  ASSERT_TRUE(man.ok()) << man.status();
  auto poser = NodePoser::Create(*man);
  ASSERT_TRUE(poser.ok()) << poser.status();
  const tinygltf::Model& model = man->gltf->model;
  double worst = 0;
  for (int j = 0; j < man->skeleton.num_joints(); ++j) {
    const tinygltf::Node& node = model.nodes[static_cast<size_t>(man->node[static_cast<size_t>(j)])];
    if (node.translation.size() != 3) continue;
    const Eigen::Vector3d own(node.translation[0], node.translation[1], node.translation[2]);
    worst = std::max(worst, (poser->bind_translation()[static_cast<size_t>(j)] - own).norm() /
                                std::max(1.0, own.norm()));
  }
  EXPECT_LT(worst, 1e-4) << "bind translations against the nodes' own (relative)";
  const int spine = man->skeleton.FindJoint("Spine");
  ASSERT_GE(spine, 0);
  EXPECT_NEAR(poser->bind_translation()[static_cast<size_t>(spine)].y(),
              model.nodes[static_cast<size_t>(man->node[static_cast<size_t>(spine)])].translation[1], 1e-4);
  EXPECT_NEAR(man->RestPositions()[static_cast<size_t>(man->roles.joint[roles::kHips])].y(), 1.01, 0.02);
  // Posed at rest, the node tree puts the hips where the rig has them.
  std::vector<double> rest(static_cast<size_t>(man->skeleton.num_channels()), 0.0);
  const int hips = man->roles.joint[roles::kHips];
  for (int a = 0; a < 3; ++a) {
    const int col = man->skeleton.joint(hips).position_column[static_cast<size_t>(a)];
    if (col >= 0) rest[static_cast<size_t>(col)] = man->skeleton.joint(hips).offset[a];
  }
  std::vector<float> q(static_cast<size_t>(man->skeleton.num_joints()) * 4), t(poser->translated_joints().size() * 3);
  ASSERT_TRUE(poser->Pose(rest, q, t).ok());
  ASSERT_FALSE(poser->translated_joints().empty());
  // The hips' node translation (in its parent's space: the scene root, unscaled).
  size_t k = 0;
  while (k < poser->translated_joints().size() && poser->translated_joints()[k] != hips) ++k;
  ASSERT_LT(k, poser->translated_joints().size());
  EXPECT_NEAR(t[k * 3 + 1], 1.0128, 0.01);
}

TEST(CompressedGltf, UncompressedFilesPassUnchanged) {
  const std::string bytes = ReadBytes(Data("characters/quaternius_man_casual.glb"));
  auto decoded = DecodeCompressedGlb(bytes, "man.glb");
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_FALSE(decoded->has_value());
}

TEST(CompressedGltf, HostileFilesAreRefusedNamingThePart) {
  const std::string bytes = ReadBytes(Data(kValidMan));
  auto refuse = [&](const std::string& what, const std::function<void(Glb&)>& damage, const std::string& part) {
    Glb g = Split(bytes);
    damage(g);
    auto r = ReadGlbFromMemory(Join(g), "man.glb");
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << what;
    EXPECT_NE(r.status().message().find("man.glb: "), std::string::npos) << what << ": " << r.status();
    EXPECT_NE(r.status().message().find(part), std::string::npos) << what << ": " << r.status();
  };
  const std::string ext = "bufferViews[6].extensions.EXT_meshopt_compression";
  refuse("a count that overflows", [](Glb& g) { g.json["bufferViews"][6]["extensions"]["EXT_meshopt_compression"]["count"] = 1e19; }, ext + ".count");
  refuse("a huge bufferView",
         [](Glb& g) {
           g.json["bufferViews"][6]["byteLength"] = 4294967295ull;
           g.json["bufferViews"][6]["extensions"]["EXT_meshopt_compression"]["count"] = 536870911;
         },
         "exceed");
  refuse("a view past its buffer", [](Glb& g) { g.json["bufferViews"][6]["extensions"]["EXT_meshopt_compression"]["byteOffset"] = 1u << 30; }, ext + ".byteLength");
  refuse("an odd stride", [](Glb& g) { g.json["bufferViews"][6]["extensions"]["EXT_meshopt_compression"]["byteStride"] = 6; }, ext + ".byteStride");
  refuse("an unknown mode", [](Glb& g) { g.json["bufferViews"][6]["extensions"]["EXT_meshopt_compression"]["mode"] = "STRIPS"; }, ext + ".mode");
  refuse("damaged compressed data",
         [](Glb& g) {
           const auto& e = g.json["bufferViews"][6]["extensions"]["EXT_meshopt_compression"];
           const size_t at = e["byteOffset"].get<size_t>();
           std::memset(g.bin.data() + at, 0x7f, 64);
         },
         ext);
  refuse("a BIN chunk shorter than the buffer", [](Glb& g) { g.bin.resize(1000); }, "buffers[0].byteLength");
  refuse("JSON nested too deep",
         [](Glb& g) {
           nlohmann::json deep = nlohmann::json::array();
           for (int i = 0; i < 100; ++i) deep = nlohmann::json::array({deep});
           g.json["extras"] = deep;
         },
         "nested deeper");
  // A truncated file.
  auto cut = ReadGlbFromMemory(std::string_view(bytes).substr(0, bytes.size() / 2), "man.glb");
  ASSERT_FALSE(cut.ok());
  EXPECT_NE(cut.status().message().find("man.glb: GLB container"), std::string::npos) << cut.status();
}

TEST(Vrm, Vrm0AndVrm1HumanoidsLoad) {
  auto godette = LoadGltfRig(Data(kGodette));
  ASSERT_TRUE(godette.ok()) << godette.status();
  EXPECT_EQ(RigFormat(*godette), "vrm0");
  EXPECT_EQ(godette->roles.family, RigFamily::kVrm);
  // VRM 0.x thumbs (Proximal, Intermediate, Distal) are the three thumb
  // bones from the hand out, each its own node.
  for (int side : {0, 1}) {
    const auto& j = godette->roles.joint;
    const int t1 = j[static_cast<size_t>(roles::Finger(side, 0, 0))], t2 = j[static_cast<size_t>(roles::Finger(side, 0, 1))],
              t3 = j[static_cast<size_t>(roles::Finger(side, 0, 2))];
    ASSERT_GE(t1, 0) << "side " << side;
    ASSERT_GE(t2, 0);
    ASSERT_GE(t3, 0);
    const std::string s = side == 0 ? "l" : "r";
    EXPECT_EQ(godette->skeleton.joint(t1).name, "thumb.1." + s + "_Armature");
    EXPECT_EQ(godette->skeleton.joint(t2).name, "thumb.2." + s + "_Armature");
    EXPECT_EQ(godette->skeleton.joint(t3).name, "thumb.3." + s + "_Armature");
    EXPECT_EQ(godette->skeleton.joint(t2).parent, t1);
  }
  auto vrm1 = LoadGltfRig(Data(kVrm1));
  ASSERT_TRUE(vrm1.ok()) << vrm1.status();
  EXPECT_EQ(RigFormat(*vrm1), "vrm1");
  // 22 humanoid bones, no skin: the joints are the humanoid's nodes, at
  // their default (rest) pose: the hips 0.5 m up, legs 0.4 m.
  EXPECT_EQ(vrm1->skeleton.num_joints(), 22);
  EXPECT_EQ(vrm1->roles.num_mapped(), 22);
  EXPECT_NEAR(vrm1->LegLength(), 0.4, 1e-5);
  const auto rest = vrm1->RestPositions();
  EXPECT_NEAR(rest[static_cast<size_t>(vrm1->roles.joint[roles::kHips])].y(), 0.5, 1e-6);
  // The head's end site is not the "Meter" node (a group of meshes below it).
  const auto& head = vrm1->skeleton.joint(vrm1->roles.joint[roles::kHead]);
  EXPECT_FALSE(head.end_site && head.end_site->y() < 0) << head.end_site->transpose();
}

TEST(Vrm, MissingHumanoidBoneIsNamed) {
  Glb g = Split(ReadBytes(Data(kVrm1)));
  g.json["extensions"]["VRMC_vrm"]["humanoid"]["humanBones"].erase("leftLowerLeg");
  auto r = ReadGlbFromMemory(Join(g), "x.vrm");
  ASSERT_TRUE(r.ok()) << r.status();
  auto rig = RigFromGltf(*r);
  ASSERT_FALSE(rig.ok());
  EXPECT_NE(rig.status().message().find("x.vrm: extensions.VRMC_vrm.humanoid.humanBones"), std::string::npos)
      << rig.status();
  EXPECT_NE(rig.status().message().find("leftLowerLeg"), std::string::npos) << rig.status();
  Glb h = Split(ReadBytes(Data(kVrm1)));
  h.json["extensions"]["VRMC_vrm"]["humanoid"]["humanBones"]["hips"]["node"] = 999;
  auto bad = RigFromGltf(*ReadGlbFromMemory(Join(h), "y.vrm"));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("humanBones.hips.node"), std::string::npos) << bad.status();
}

// Retargeting onto the VRM 1.0 humanoid: the same facing and feet measures
// kinemo retarget --json prints, on both BEAT2 takes; without planting for
// the baseline. Its feet are adult-size (ankle -> toes 0.14 m, 45 deg down)
// on 0.4 m legs: while the feet took the source's ankle -> ball pitch (24
// deg) rather than keeping its own flat rest, its toes floated 2-6 cm and
// the feet slid 0.05-0.09 m/s p95 planted.
TEST(Vrm, RetargetOntoVrm1KeepsFacingAndFeet) {
  auto vrm1 = LoadGltfRig(Data(kVrm1));
  ASSERT_TRUE(vrm1.ok());
  for (const char* file : {"paired/beat2/2_scott_0_1_1.bvh", "paired/beat2/2_scott_0_2_2.bvh"}) {
    auto clip = motion::ReadBvhFile(Data(file));
    ASSERT_TRUE(clip.ok());
    auto src = RigFromSkeleton(clip->skeleton, 0.01, file);
    ASSERT_TRUE(src.ok());
    for (bool plant : {false, true}) {
      RetargetOptions o;
      o.plant_feet = plant;
      o.frame_time_s = clip->frame_time_s;
      auto rt = Retargeter::Create(clip->skeleton, *src, *vrm1, o);
      ASSERT_TRUE(rt.ok()) << rt.status();
      auto out = rt->RetargetClip(*clip);
      ASSERT_TRUE(out.ok());
      motion::MotionCheckParams params;
      params.contact = ContactParamsFor(*vrm1);
      auto feet = motion::CheckMotion(*out, RegionsFromRoles(*vrm1), params, nullptr);
      ASSERT_TRUE(feet.ok());
      auto facing = CompareFacings(*clip, *src, *out, *vrm1, rt->world_axes());
      ASSERT_TRUE(facing.ok());
      double axes = 0;
      for (int part = 0; part < kNumFacingParts; ++part) {
        axes = std::max({axes, facing->up_p95_deg[part], facing->forward_p95_deg[part]});
      }
      std::printf("[vrm1] %s plant %d: slide p95 %.4f m/s (%d samples, contact %.2f), lowest sole %.3f m, "
                  "trunk/head axes p95 %.2f deg, shoulder line %.2f deg\n",
                  file, plant, feet->foot_slide_p95_m_s, feet->contact_samples, feet->contact_fraction,
                  feet->min_foot_height_m, axes, facing->shoulder_left_p95_deg);
      EXPECT_LE(axes, 5.0) << file;
      EXPECT_LE(facing->shoulder_left_p95_deg, 5.0) << file;
      if (plant) {
        EXPECT_LE(feet->foot_slide_p95_m_s, 0.01) << file;
        EXPECT_GT(feet->contact_samples, 2000) << file;
        EXPECT_GT(feet->min_foot_height_m, -0.02) << file;
      }
    }
  }
}

}  // namespace
}  // namespace kinemo::retarget

