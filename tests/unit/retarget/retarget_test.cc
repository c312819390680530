// Retargeting on real data: role detection on every skeleton family kinemo
// has, identity onto the own rig, SMPL-X -> Quaternius -> SMPL-X directions,
// feet after retargeting, bind pose (not default pose) of a glTF rig.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/motion/motion_check.h"
#include "common/retarget/measures.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"
#include "tests/unit/retarget/test_data.h"

namespace kinemo::retarget {
namespace {

using namespace roles;

using test::Data;

motion::Clip Load(const std::string& rel, int max_frames = 0) {
  auto clip = motion::ReadBvhFile(Data(rel));
  EXPECT_TRUE(clip.ok()) << clip.status();
  if (!clip.ok()) return {};
  if (max_frames > 0 && clip->num_frames() > max_frames) clip->frames.conservativeResize(max_frames, clip->frames.cols());
  return *std::move(clip);
}

const char* kSmplx = "paired/beat2/2_scott_0_1_1.bvh";
const char* kMan = "characters/quaternius_man_casual.glb";
constexpr double kFacingBoundDeg = 1.0;  // trunk and head axes, p95

double P95(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(std::ceil(0.95 * static_cast<double>(v.size()))) - 1];
}

TEST(Roles, NamesRoundTripAndChains) {
  for (int r = 0; r < kNumRoles; ++r) {
    ASSERT_EQ(ParseRole(RoleName(r)), r) << RoleName(r);
    if (r != kHips) {
      EXPECT_GE(ParentRole(r), 0) << RoleName(r);
    }
    if (ChildRole(r) >= 0) {
      EXPECT_GT(ChildRole(r), r) << RoleName(r);
    }
  }
  EXPECT_EQ(RoleName(Side(0, kUpperArm)), "left_upper_arm");
  EXPECT_EQ(RoleName(Finger(1, 4, 2)), "right_little3");
  EXPECT_EQ(ChildRole(Side(0, kHand)), Finger(0, 2, 0));
}

TEST(Roles, DetectsEveryKinemoSkeletonFamily) {
  const std::vector<std::pair<std::string, RigFamily>> files = {
      {kSmplx, RigFamily::kSmplx},
      {"motion/dataset-1_bye_normal_001.bvh", RigFamily::kBandai},
      {"motion/131_01.bvh", RigFamily::kCmu31},
      {"motion/cmu_002_03.bvh", RigFamily::kCmuIclone}};
  for (const auto& [file, family] : files) {
    const motion::Clip clip = Load(file, 2);
    auto rig = RigFromSkeleton(clip.skeleton, 0.01, file);
    ASSERT_TRUE(rig.ok()) << file << ": " << rig.status();
    EXPECT_EQ(rig->roles.family, family) << file;
    EXPECT_TRUE(MissingRequiredRoles(rig->roles.joint).empty()) << file;
  }
  const motion::Clip smplx = Load(kSmplx, 2);
  auto rig = RigFromSkeleton(smplx.skeleton, 0.01, "smplx");
  ASSERT_TRUE(rig.ok());
  EXPECT_EQ(rig->skeleton.joint(rig->roles.joint[Side(0, kUpperArm)]).name, "left_shoulder");
  EXPECT_EQ(rig->skeleton.joint(rig->roles.joint[Side(1, kToes)]).name, "right_foot");
  EXPECT_EQ(rig->skeleton.joint(rig->roles.joint[Finger(0, 1, 2)]).name, "left_index3");
}

TEST(Roles, JsonMapAndMissingRolesAreNamed) {
  const motion::Clip clip = Load("motion/dataset-1_bye_normal_001.bvh", 2);
  RoleMapChoice choice;
  choice.map_json = R"({"hips": "Hips", "spine": "Spine", "head": "Head", "left_upper_arm": "UpperArm_L"})";
  choice.map_source = "my_map.json";
  auto rig = RigFromSkeleton(clip.skeleton, 0.01, "bandai", choice);
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), absl::StatusCode::kInvalidArgument);
  const std::string msg(rig.status().message());
  EXPECT_NE(msg.find("right_upper_arm"), std::string::npos) << msg;
  EXPECT_NE(msg.find("left_shin"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("left_upper_arm,"), std::string::npos) << msg;

  choice.map_json = R"({"hips": "NoSuchJoint"})";
  rig = RigFromSkeleton(clip.skeleton, 0.01, "bandai", choice);
  ASSERT_FALSE(rig.ok());
  EXPECT_NE(std::string(rig.status().message()).find("my_map.json: hips"), std::string::npos) << rig.status();
  choice.map_json = R"({"elbow": "Hips"})";
  rig = RigFromSkeleton(clip.skeleton, 0.01, "bandai", choice);
  ASSERT_FALSE(rig.ok());
  EXPECT_NE(std::string(rig.status().message()).find("my_map.json: elbow"), std::string::npos) << rig.status();
  choice.map_json = "[1,2";
  EXPECT_FALSE(RigFromSkeleton(clip.skeleton, 0.01, "bandai", choice).ok());
}

TEST(GltfRig, QuaterniusManIsDetectedInMetres) {
  auto rig = LoadGltfRig(Data(kMan));
  ASSERT_TRUE(rig.ok()) << rig.status();
  EXPECT_EQ(rig->roles.family, RigFamily::kQuaternius);
  EXPECT_EQ(rig->skeleton.num_joints(), 49);
  EXPECT_EQ(rig->skeleton.joint(rig->roles.joint[Finger(0, 1, 0)]).name, "Index2.L");
  const auto p = rig->RestPositions();
  const double head_y = p[rig->roles.joint[kHead]].y();
  EXPECT_GT(head_y, 1.3);  // a standing adult, metres
  EXPECT_LT(head_y, 2.0);
  EXPECT_GT(rig->LegLength(), 0.6);
  EXPECT_LT(rig->LegLength(), 1.1);
  // Bind pose is a T-pose: the left arm points to +x (the character's left), level.
  const Eigen::Vector3d arm = p[rig->roles.joint[Side(0, kForearm)]] - p[rig->roles.joint[Side(0, kUpperArm)]];
  EXPECT_GT(arm.normalized().x(), 0.9) << arm.transpose();
}

TEST(GltfRig, RestIsTheBindPoseNotTheNodeDefaultPose) {
  // robot_expressive.glb: arms down in the node default pose, a T-pose in its
  // inverseBindMatrices.
  auto rig = LoadGltfRig(Data("characters/robot_expressive.glb"));
  ASSERT_TRUE(rig.ok()) << rig.status();
  const auto p = rig->RestPositions();
  for (int side = 0; side < 2; ++side) {
    const Eigen::Vector3d arm =
        (p[rig->roles.joint[Side(side, kForearm)]] - p[rig->roles.joint[Side(side, kUpperArm)]]).normalized();
    EXPECT_LT(std::abs(arm.y()), 0.35) << "side " << side << ": " << arm.transpose();
  }
}

TEST(GltfRig, ErrorsAreClear) {
  auto missing = LoadGltfRig(Data("characters/no_such.glb"));
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  auto not_gltf = LoadGltfRig(Data(kSmplx));
  EXPECT_EQ(not_gltf.status().code(), absl::StatusCode::kInvalidArgument);
}

// Local rotation angle between two frames of the same skeleton, per joint.
double MaxLocalRotationError(const motion::Clip& a, const motion::Clip& b) {
  double worst = 0;
  for (int f = 0; f < a.num_frames(); ++f) {
    for (int j = 0; j < a.skeleton.num_joints(); ++j) {
      const Eigen::Matrix3d ra = motion::LocalRotation(a.skeleton.joint(j), a.frame(f));
      const Eigen::Matrix3d rb = motion::LocalRotation(b.skeleton.joint(j), b.frame(f));
      worst = std::max(worst, Eigen::AngleAxisd(ra.transpose() * rb).angle());
    }
  }
  return worst;
}

TEST(Retarget, OntoItsOwnRigIsTheIdentity) {
  for (const char* file : {kSmplx, "motion/dataset-1_bye_normal_001.bvh", "motion/131_01.bvh"}) {
    const motion::Clip clip = Load(file, 300);
    auto rig = RigFromSkeleton(clip.skeleton, 0.01, file);
    ASSERT_TRUE(rig.ok()) << rig.status();
    RetargetOptions transfer_only;  // no foot planting: the transfer itself
    transfer_only.plant_feet = false;
    auto out = RetargetClip(clip, 0.01, *rig, transfer_only);
    ASSERT_TRUE(out.ok()) << out.status();
    ASSERT_EQ(out->clip.num_frames(), clip.num_frames());
    EXPECT_NEAR(out->root_scale, 1.0, 1e-12);
    const double err = MaxLocalRotationError(clip, out->clip);
    std::printf("[identity] %s: max local rotation error %.2e rad over %d frames x %d joints\n", file, err,
                clip.num_frames(), clip.skeleton.num_joints());
    EXPECT_LE(err, 1e-4) << file;
    // The hips land where they were.
    auto a = motion::ComputeWorldPose(clip, clip.num_frames() - 1);
    auto b = motion::ComputeWorldPose(out->clip, clip.num_frames() - 1);
    const int hips = rig->roles.joint[kHips];
    EXPECT_LT((a->positions[hips] - b->positions[hips]).norm(), 1e-6) << file;
  }
}

TEST(Retarget, OntoTheCharacterAndBackOntoItsGltfRigIsTheIdentity) {
  const motion::Clip clip = Load(kSmplx, 300);
  auto man = LoadGltfRig(Data(kMan));
  ASSERT_TRUE(man.ok()) << man.status();
  auto on_man = RetargetClip(clip, 0.01, *man);
  ASSERT_TRUE(on_man.ok()) << on_man.status();
  // That clip (on the man's rest skeleton) onto the man's glTF rig again.
  RetargetOptions transfer_only;
  transfer_only.plant_feet = false;
  auto again = Retargeter::Create(on_man->clip.skeleton, *man, *man, transfer_only);
  ASSERT_TRUE(again.ok()) << again.status();
  auto twice = again->RetargetClip(on_man->clip);
  ASSERT_TRUE(twice.ok());
  const double err = MaxLocalRotationError(on_man->clip, *twice);
  std::printf("[identity] SMPL-X on the Quaternius man, onto the man again: max error %.2e rad\n", err);
  EXPECT_LE(err, 1e-4);
}

TEST(Retarget, SmplxToQuaterniusAndBackKeepsArmDirections) {
  const motion::Clip clip = Load(kSmplx);
  auto smplx = RigFromSkeleton(clip.skeleton, 0.01, "smplx");
  auto man = LoadGltfRig(Data(kMan));
  ASSERT_TRUE(smplx.ok() && man.ok());
  RetargetOptions transfer_only;  // arms: foot planting changes legs only, but keep it pure
  transfer_only.plant_feet = false;
  auto there = RetargetClip(clip, 0.01, *man, transfer_only);
  ASSERT_TRUE(there.ok()) << there.status();
  auto back_rt = Retargeter::Create(there->clip.skeleton, *man, *smplx, transfer_only);
  ASSERT_TRUE(back_rt.ok()) << back_rt.status();
  auto back = back_rt->RetargetClip(there->clip);
  ASSERT_TRUE(back.ok());
  for (int side = 0; side < 2; ++side) {
    for (int bone : {kUpperArm, kForearm, kHand}) {
      const Role role = Side(side, bone);
      auto a = BoneDirections(clip, *smplx, role);
      auto b = BoneDirections(*back, *smplx, role);
      auto m = BoneDirections(there->clip, *man, role);
      ASSERT_TRUE(a.ok() && b.ok() && m.ok());
      ASSERT_EQ(a->size(), b->size());
      ASSERT_FALSE(a->empty());
      std::vector<double> err, err_man;
      for (size_t f = 0; f < a->size(); ++f) {
        err.push_back(std::acos(std::clamp((*a)[f].dot((*b)[f]), -1.0, 1.0)) * 180 / M_PI);
        err_man.push_back(std::acos(std::clamp((*a)[f].dot((*m)[f]), -1.0, 1.0)) * 180 / M_PI);
      }
      std::printf("[round trip] %-16s angle error p95 %.3f deg (on the man: p95 %.3f deg), %zu frames\n",
                  std::string(RoleName(role)).c_str(), P95(err), P95(err_man), err.size());
      EXPECT_LE(P95(err), 5.0) << RoleName(role);
    }
  }
}

// Trunk and head facing (measures.h Facings) of the source and of its
// retargeting onto the man: the hips, chest, neck and head point and face as
// the source's do. Before the per-role rest frames (retarget.h) the trunk and
// head followed the rigs' bone directions: on BEAT2 take 1 the man's chest,
// neck and head were 11.8 deg off (p95), on Bandai "bye" the chest and head
// faced 91 deg away (shoulder line 58 deg off).
TEST(Retarget, TrunkAndHeadFaceAsTheSourceDoes) {
  auto man = LoadGltfRig(Data(kMan));
  ASSERT_TRUE(man.ok());
  for (const char* file : {kSmplx, "motion/dataset-1_bye_normal_001.bvh", "motion/131_01.bvh"}) {
    const motion::Clip clip = Load(file, 1800);
    auto src_rig = RigFromSkeleton(clip.skeleton, 0.01, file);
    ASSERT_TRUE(src_rig.ok());
    RetargetOptions transfer_only;
    transfer_only.plant_feet = false;
    auto rt = Retargeter::Create(clip.skeleton, *src_rig, *man, transfer_only);
    ASSERT_TRUE(rt.ok()) << rt.status();
    auto out = rt->RetargetClip(clip);
    ASSERT_TRUE(out.ok());
    auto e = CompareFacings(clip, *src_rig, *out, *man, rt->world_axes());
    ASSERT_TRUE(e.ok()) << e.status();
    std::printf("[facing] %s (%d frames), p95 deg:", file, clip.num_frames());
    for (int part = 0; part < kNumFacingParts; ++part) {
      std::printf(" %s up %.1f fwd %.1f;", FacingPartName(part), e->up_p95_deg[part], e->forward_p95_deg[part]);
    }
    std::printf(" pelvis left %.1f, shoulder left %.1f, neck->head %.1f\n", e->pelvis_left_p95_deg,
                e->shoulder_left_p95_deg, e->neck_to_head_p95_deg);
    for (int part = 0; part < kNumFacingParts; ++part) {
      EXPECT_LE(e->up_p95_deg[part], kFacingBoundDeg) << file << " " << FacingPartName(part);
      EXPECT_LE(e->forward_p95_deg[part], kFacingBoundDeg) << file << " " << FacingPartName(part);
    }
    // From joint positions alone: the shoulder line within 5 deg of the
    // source's; the line between the thighs within 1 deg of the angle the
    // two rest poses already differ by (the BEAT2 speaker's hips are 6.7 deg
    // out of level at rest, the man's level).
    EXPECT_LE(e->shoulder_left_p95_deg, 5.0) << file;
    const auto ps = src_rig->RestPositions(), pm = man->RestPositions();
    auto left = [](const Rig& rig, const std::vector<Eigen::Vector3d>& p) {
      return Eigen::Vector3d(p[rig.roles.joint[Side(0, kThigh)]] - p[rig.roles.joint[Side(1, kThigh)]]).normalized();
    };
    const double rest_deg =
        std::acos(std::clamp((rt->world_axes() * left(*src_rig, ps)).dot(left(*man, pm)), -1.0, 1.0)) * 180 / M_PI;
    if (rest_deg < 10) {  // an upright rest (Bandai's lies down: its thighs are not comparable at rest)
      EXPECT_LE(e->pelvis_left_p95_deg, rest_deg + 1.0) << file << ", rest offset " << rest_deg;
    } else {
      EXPECT_LE(e->pelvis_left_p95_deg, 5.0) << file;
    }
  }
}

// Foot slide (feet.h terms) of a clip and of its retargeting onto the man.
struct FeetResult {
  motion::MotionCheck source, target;
};
FeetResult CheckFeet(const char* file, const Rig& man) {
  const motion::Clip clip = Load(file);
  auto src_rig = RigFromSkeleton(clip.skeleton, 0.01, file);
  EXPECT_TRUE(src_rig.ok());
  auto out = RetargetClip(clip, 0.01, man);  // foot planting on (the default)
  EXPECT_TRUE(out.ok()) << out.status();
  motion::MotionCheckParams src_params;
  src_params.contact.meters_per_unit = 0.01;
  auto src = motion::CheckMotion(clip, RegionsFromRoles(*src_rig), src_params, nullptr);
  motion::MotionCheckParams params;
  params.contact.meters_per_unit = 1.0;
  auto dst = motion::CheckMotion(out->clip, RegionsFromRoles(man), params, nullptr);
  EXPECT_TRUE(src.ok() && dst.ok());
  std::printf("[feet] %s: source slide p95 %.4f m/s (%d samples)  on the man %.4f m/s (%d samples, contact %.2f), "
              "lowest sole %.3f m, root scale %.3f\n",
              file, src->foot_slide_p95_m_s, src->contact_samples, dst->foot_slide_p95_m_s, dst->contact_samples,
              dst->contact_fraction, dst->min_foot_height_m, out->root_scale);
  auto hands_src = CheckHandsInTorso(clip, *src_rig);
  auto hands_dst = CheckHandsInTorso(out->clip, man);
  EXPECT_TRUE(hands_src.ok() && hands_dst.ok());
  std::printf("[hands in torso] %s: source %.1f%% of frames, on the man %.1f%% (deepest %.3f m)\n", file,
              100 * hands_src->fraction(), 100 * hands_dst->fraction(), hands_dst->deepest_m);
  return {*src, *dst};
}

TEST(Retarget, FeetStayPlantedOnTheCharacter) {
  auto man = LoadGltfRig(Data(kMan));
  ASSERT_TRUE(man.ok());
  // Bandai "bye": the actor stands still (source slide 0.0004 m/s p95); on
  // the man the feet must stand as still.
  const FeetResult bandai = CheckFeet("motion/dataset-1_bye_normal_001.bvh", *man);
  EXPECT_GT(bandai.target.contact_samples, 50);
  EXPECT_LE(bandai.target.foot_slide_p95_m_s, 0.01);
  EXPECT_GT(bandai.target.min_foot_height_m, -0.02);  // no sinking into the floor
  // BEAT2 speakers shift their weight and shuffle (the SMPL-X sources slide
  // 0.06-0.14 m/s p95 themselves): planted, the man's feet meet the target
  // too (take 1 slid 0.031 m/s p95 while a far lock was dragged during the
  // other foot's step; feet.h).
  for (const char* file : {kSmplx, "paired/beat2/2_scott_0_2_2.bvh"}) {
    const FeetResult beat = CheckFeet(file, *man);
    EXPECT_GT(beat.target.contact_samples, 1000) << file;
    EXPECT_LT(beat.target.foot_slide_p95_m_s, beat.source.foot_slide_p95_m_s) << file;
    EXPECT_LE(beat.target.foot_slide_p95_m_s, 0.01) << file;
    EXPECT_GT(beat.target.min_foot_height_m, -0.02) << file;
  }
}

TEST(Retarget, EveryFamilyDrivesTheCharacter) {
  auto man = LoadGltfRig(Data(kMan));
  ASSERT_TRUE(man.ok());
  for (const char* file : {"motion/dataset-1_bye_normal_001.bvh", "motion/131_01.bvh", "motion/cmu_002_03.bvh"}) {
    const motion::Clip clip = Load(file, 120);
    auto out = RetargetClip(clip, 0.01, *man);
    ASSERT_TRUE(out.ok()) << file << ": " << out.status();
    EXPECT_GT(out->mapped_roles.size(), 14u) << file;
    // The character's hands move with the source's.
    auto first = motion::ComputeWorldPose(out->clip, 0);
    double moved = 0;
    for (int f = 1; f < out->clip.num_frames(); ++f) {
      auto pose = motion::ComputeWorldPose(out->clip, f);
      for (int side = 0; side < 2; ++side) {
        const int hand = man->roles.joint[Side(side, kHand)];
        moved = std::max(moved, (first->positions[hand] - pose->positions[hand]).norm());
      }
    }
    EXPECT_GT(moved, 0.05) << file;
  }
}

}  // namespace
}  // namespace kinemo::retarget
