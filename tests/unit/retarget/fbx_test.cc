// FBX rigs (common/retarget/fbx.h) on real files: the Quaternius man as
// Blender 3.4's own FBX exporter wrote it (tests/data/characters/formats,
// make_fbx.py), with its own bone names, renamed to Mixamo's (mixamorig:)
// and, skeleton alone, to Character Creator's (CC_Base_). Each must be the
// same character as the GLB it came from (rest pose, legs, roles, mesh), in
// metres though the files are in centimetres; damaged and hostile bytes are
// refused naming the file and the part; retargeting BEAT2 onto it keeps the
// facing and the feet.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "common/motion/bvh.h"
#include "common/motion/motion_check.h"
#include "common/retarget/face_map.h"
#include "common/retarget/fbx.h"
#include "common/retarget/gltf.h"
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

const char* kManGlb = "characters/quaternius_man_casual.glb";
const char* kManFbx = "characters/formats/quaternius_man.fbx";
const char* kMixamoFbx = "characters/formats/quaternius_man_mixamo.fbx";
const char* kCcFbx = "characters/formats/quaternius_man_cc_armature.fbx";
const char* kRobotFbx = "characters/formats/robot_expressive.fbx";

std::string Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Rest world positions (metres) per role.
std::map<int, Eigen::Vector3d> RolePositions(const Rig& rig) {
  const std::vector<Eigen::Vector3d> p = rig.RestPositions();
  std::map<int, Eigen::Vector3d> out;
  for (int r = 0; r < kNumRoles; ++r) {
    if (rig.roles.joint[r] >= 0) out[r] = p[rig.roles.joint[r]] * rig.meters_per_unit;
  }
  return out;
}

TEST(Fbx, BlenderExportIsTheSameRigAsItsGlb) {
  auto glb = LoadGltfRig(Data(kManGlb));
  ASSERT_TRUE(glb.ok()) << glb.status();
  const std::map<int, Eigen::Vector3d> want = RolePositions(*glb);
  struct Case {
    const char* file;
    RigFamily family;
  };
  for (const Case& c : {Case{kManFbx, RigFamily::kQuaternius}, Case{kMixamoFbx, RigFamily::kMixamo},
                        Case{kCcFbx, RigFamily::kCmuIclone}}) {
    SCOPED_TRACE(c.file);
    auto rig = LoadGltfRig(Data(c.file));
    ASSERT_TRUE(rig.ok()) << rig.status();
    EXPECT_EQ(RigFormat(*rig), "fbx");
    EXPECT_EQ(rig->roles.family, c.family) << RigFamilyName(rig->roles.family);
    // Blender writes centimetres (UnitScaleFactor 1); the rig is in metres.
    EXPECT_DOUBLE_EQ(rig->gltf->source_meters_per_unit, 0.01);
    EXPECT_DOUBLE_EQ(rig->meters_per_unit, 1.0);
    EXPECT_NEAR(rig->LegLength(), glb->LegLength(), 1e-4);
    EXPECT_NEAR(rig->HipsHeight(), glb->HipsHeight(), 1e-4);
    // Every role the GLB maps (fingers included), at the same place.
    const std::map<int, Eigen::Vector3d> got = RolePositions(*rig);
    EXPECT_EQ(got.size(), want.size());
    double worst = 0;
    int worst_role = -1;
    for (const auto& [role, p] : want) {
      auto it = got.find(role);
      ASSERT_NE(it, got.end()) << RoleName(role);
      if ((it->second - p).norm() > worst) {
        worst = (it->second - p).norm();
        worst_role = role;
      }
    }
    EXPECT_LT(worst, 1e-4) << "metres, at " << RoleName(worst_role);
    // The anatomical axes of the rest pose agree (the rig faces +z as the GLB does).
    EXPECT_LT((rig->RestBodyAxes().upper - glb->RestBodyAxes().upper).norm(), 1e-4);
    EXPECT_LT((rig->RestBodyAxes().pelvis - glb->RestBodyAxes().pelvis).norm(), 1e-4);
  }
}

TEST(Fbx, SkinnedMeshIsWhereTheGlbsIs) {
  auto glb = LoadGltfRig(Data(kManGlb));
  auto fbx = LoadGltfRig(Data(kManFbx));
  ASSERT_TRUE(glb.ok() && fbx.ok());
  auto a = LoadCharacterMesh(*glb);
  auto b = LoadCharacterMesh(*fbx);
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(a->triangles.size(), b->triangles.size());
  EXPECT_LT((a->min_corner - b->min_corner).norm(), 1e-3);
  EXPECT_LT((a->max_corner - b->max_corner).norm(), 1e-3);
  EXPECT_GT(b->max_corner.y(), 1.5f);  // a man standing on y = 0, in metres
  EXPECT_NEAR(b->min_corner.y(), 0.0f, 0.02f);
  // Posed by the same frame, the two meshes move alike: the right hand's
  // vertices follow the right hand (a raised arm moves them by decimetres).
  std::vector<double> frame(static_cast<size_t>(fbx->skeleton.num_channels()), 0.0);
  const int arm = fbx->roles.joint[roles::Side(1, roles::kUpperArm)];
  ASSERT_GE(arm, 0);
  frame[static_cast<size_t>(fbx->skeleton.joint(arm).first_channel)] = 60;  // Z rotation, degrees
  SkinPose pose;
  ASSERT_TRUE(ComputeSkinPose(*fbx, frame, &pose).ok());
  std::vector<Eigen::Vector3f> moved;
  SkinMesh(*b, pose, &moved, nullptr);
  double farthest = 0;
  for (size_t i = 0; i < moved.size(); ++i) farthest = std::max(farthest, double((moved[i] - b->positions[i]).norm()));
  EXPECT_GT(farthest, 0.3);
  EXPECT_LT(farthest, 2.0);
}

// The robot as Blender exported it: meshes hanging rigidly under bones (no
// skin clusters: each follows its node's nearest joint) and the head's three
// shape keys as FBX blend shapes, which must become morph targets the face
// map finds by name and drives.
TEST(Fbx, BlendShapesBecomeMorphTargetsTheFaceDrives) {
  auto glb = LoadGltfRig(Data("characters/robot_expressive.glb"));
  auto rig = LoadGltfRig(Data(kRobotFbx));
  ASSERT_TRUE(glb.ok() && rig.ok()) << rig.status();
  EXPECT_EQ(RigFormat(*rig), "fbx");
  EXPECT_EQ(rig->UnmappedRoles(), glb->UnmappedRoles());
  EXPECT_NEAR(rig->LegLength(), glb->LegLength(), 1e-3);
  auto face = FaceMap::Create(*rig);
  ASSERT_TRUE(face.ok()) << face.status();
  std::map<std::string, int> driven;
  for (const FaceControl& c : face->controls()) {
    if (c.kind == FaceControlKind::kMorphTarget && c.driven()) ++driven[c.name];
  }
  // assimp splits the head by material: each part carries the three shapes.
  EXPECT_GE(driven["Angry"], 1);
  EXPECT_GE(driven["Surprised"], 1);
  EXPECT_GE(driven["Sad"], 1);
  face::FaceFrame frame;
  frame.expression = face::Expression::kAngry;
  frame.expression_weight = 1;
  std::vector<float> weights(face->controls().size());
  face->Weights(frame, weights);
  float angry = 0;
  for (size_t i = 0; i < weights.size(); ++i) {
    if (face->controls()[i].name == "Angry") angry = std::max(angry, weights[i]);
  }
  EXPECT_GT(angry, 0.9f);
  auto mesh = LoadCharacterMesh(*rig);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_GT(mesh->triangles.size(), 2000u);
}

TEST(Fbx, DamagedFilesAreRefusedNamingTheFile) {
  const std::string bytes = Bytes(Data(kCcFbx));
  ASSERT_GT(bytes.size(), 10000u);
  // (The binary footer after the last record is not needed: cuts end before it.)
  for (size_t cut : {size_t{0}, size_t{10}, size_t{27}, size_t{100}, bytes.size() / 10, bytes.size() / 2,
                     bytes.size() - 300}) {
    auto src = ReadFbxFromMemory(std::string_view(bytes).substr(0, cut), "cut.fbx");
    ASSERT_FALSE(src.ok()) << cut;
    EXPECT_EQ(src.status().code(), absl::StatusCode::kInvalidArgument) << cut << ": " << src.status();
    EXPECT_EQ(src.status().message().rfind("cut.fbx: ", 0), 0u) << src.status();
  }
  auto text = ReadFbxFromMemory("; just text\n", "notes.fbx");
  ASSERT_FALSE(text.ok());
  EXPECT_NE(text.status().message().find("notes.fbx: not an FBX file"), std::string::npos) << text.status();
  auto missing = ReadFbx(Data("characters/formats/no_such.fbx"));
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
}

// A binary FBX of one record holding an array whose stated count would make
// assimp allocate 16 GiB: refused before assimp sees it.
TEST(Fbx, HugeArrayCountIsRefusedBeforeParsing) {
  std::string f = "Kaydara FBX Binary  ";
  f += std::string("\0\x1a\0", 3);
  auto u32 = [&](std::uint32_t v) { f.append(reinterpret_cast<const char*>(&v), 4); };
  u32(7400);
  const size_t record = f.size();
  const std::string name = "Vertices";
  const std::uint32_t props_len = 1 + 12 + 16;
  u32(static_cast<std::uint32_t>(record + 13 + name.size() + props_len));  // end offset
  u32(1);                                                                   // properties
  u32(props_len);
  f += static_cast<char>(name.size());
  f += name;
  f += 'd';
  u32(0x7fffffff);  // elements
  u32(1);           // deflated
  u32(16);
  f += std::string(16, '\0');
  f += std::string(13, '\0');  // the null record
  auto src = ReadFbxFromMemory(f, "huge.fbx");
  ASSERT_FALSE(src.ok());
  EXPECT_EQ(src.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(src.status().message().find("huge.fbx: FBX structure at byte"), std::string::npos) << src.status();
  EXPECT_NE(src.status().message().find("2147483647 elements"), std::string::npos) << src.status();
}

// A skeleton that lacks a required bone (the left calf renamed in the
// file's bytes, same length) is refused naming the role.
TEST(Fbx, MissingBoneIsNamed) {
  std::string bytes = Bytes(Data(kCcFbx));
  size_t n = 0;
  for (size_t at = bytes.find("CC_Base_L_Calf"); at != std::string::npos; at = bytes.find("CC_Base_L_Calf", at)) {
    bytes.replace(at, 14, "CC_Base_L_Xxxx");
    ++n;
  }
  ASSERT_GT(n, 0u);
  auto src = ReadFbxFromMemory(bytes, "calfless.fbx");
  ASSERT_TRUE(src.ok()) << src.status();
  auto rig = RigFromGltf(*src);
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(rig.status().message().rfind("calfless.fbx: skeleton: ", 0), 0u) << rig.status();
  EXPECT_NE(rig.status().message().find("missing roles: left_shin"), std::string::npos) << rig.status();
}

TEST(Fbx, RetargetOntoTheFbxManKeepsFacingAndFeet) {
  auto man = LoadGltfRig(Data(kMixamoFbx));
  ASSERT_TRUE(man.ok()) << man.status();
  for (const char* file : {"paired/beat2/2_scott_0_1_1.bvh", "paired/beat2/2_scott_0_2_2.bvh"}) {
    auto clip = motion::ReadBvhFile(Data(file));
    ASSERT_TRUE(clip.ok());
    auto src = RigFromSkeleton(clip->skeleton, 0.01, file);
    ASSERT_TRUE(src.ok());
    RetargetOptions o;
    o.frame_time_s = clip->frame_time_s;
    auto rt = Retargeter::Create(clip->skeleton, *src, *man, o);
    ASSERT_TRUE(rt.ok()) << rt.status();
    auto out = rt->RetargetClip(*clip);
    ASSERT_TRUE(out.ok());
    motion::MotionCheckParams params;
    params.contact = ContactParamsFor(*man);
    auto feet = motion::CheckMotion(*out, RegionsFromRoles(*man), params, nullptr);
    ASSERT_TRUE(feet.ok());
    auto facing = CompareFacings(*clip, *src, *out, *man, rt->world_axes());
    ASSERT_TRUE(facing.ok());
    double axes = 0;
    for (int part = 0; part < kNumFacingParts; ++part) {
      axes = std::max({axes, facing->up_p95_deg[part], facing->forward_p95_deg[part]});
    }
    std::printf("[fbx mixamo] %s: slide p95 %.4f m/s (contact %.2f), lowest sole %.3f m, trunk/head axes p95 "
                "%.2f deg, shoulder line %.2f deg\n",
                file, feet->foot_slide_p95_m_s, feet->contact_fraction, feet->min_foot_height_m, axes,
                facing->shoulder_left_p95_deg);
    EXPECT_LE(axes, 1.0) << file;
    EXPECT_LE(facing->shoulder_left_p95_deg, 5.0) << file;
    EXPECT_LE(feet->foot_slide_p95_m_s, 0.01) << file;
    EXPECT_GT(feet->min_foot_height_m, -0.03) << file;
  }
}

}  // namespace
}  // namespace kinemo::retarget
