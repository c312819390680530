// Face channels onto the rigs' own face controls (common/retarget/face_map.h)
// on the real characters of tests/data/characters: the VALID man's Rocketbox
// visemes with their teeth, Godette's VRM 0.x presets, the VRM 1.0 test
// model's expressions, the robot's three expression morphs, a map file, the
// SMPL-X jaw, and the GLB's morph weight animation.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/retarget/face_map.h"
#include "common/retarget/gltf.h"
#include "common/retarget/retarget.h"
#include "common/retarget/rig.h"
#include "common/retarget/rig_info.h"
#include "tests/unit/retarget/test_data.h"

namespace kinemo::retarget {
namespace {

using test::Data;

Rig LoadRig(const std::string& rel) {
  auto rig = LoadGltfRig(Data(rel));
  EXPECT_TRUE(rig.ok()) << rel << ": " << rig.status();
  return rig.ok() ? *std::move(rig) : Rig();
}

// The control named `name` (and on `mesh`, when given), or -1.
int Find(const FaceMap& map, const std::string& name, const std::string& mesh = "") {
  for (size_t c = 0; c < map.controls().size(); ++c) {
    const FaceControl& fc = map.controls()[c];
    if (fc.name == name && (mesh.empty() || fc.mesh == mesh)) return static_cast<int>(c);
  }
  return -1;
}

// A frame of one OVR viseme (weight 1) with the given jaw opening.
face::FaceFrame Viseme(face::OvrViseme v, float jaw_deg = 10) {
  face::FaceFrame f;
  f.ovr[static_cast<size_t>(v)] = 1;
  f.jaw_open_deg = jaw_deg;
  return f;
}

std::vector<float> Weights(const FaceMap& map, const face::FaceFrame& f) {
  std::vector<float> w(map.controls().size());
  map.Weights(f, w);
  return w;
}

TEST(FaceMap, ValidManRocketboxVisemesWithTheirTeeth) {
  const Rig man = LoadRig("characters/valid_white_m_1_casual.glb");
  auto map = FaceMap::Create(man);
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_EQ(map->mouth_family(), "rocketbox");
  EXPECT_LT(map->jaw().joint, 0);  // no jaw bone: MouthOpen opens the mouth
  const int aa = Find(*map, "h_expressions.AE_AA_h"), mpb = Find(*map, "h_expressions.MPB_Up_h"),
            open = Find(*map, "h_expressions.MouthOpen_h"), teeth = Find(*map, "h_teeth.t_AE_AA_h"),
            teeth_mpb = Find(*map, "h_teeth.t_MPB_h"), blink_l = Find(*map, "h_expressions.LeyeClose_h"),
            smile = Find(*map, "h_expressions.RsmileClose_h"), curl = Find(*map, "h_teeth.CurlUp_Out_tg_h");
  for (int c : {aa, mpb, open, teeth, teeth_mpb, blink_l, smile, curl}) ASSERT_GE(c, 0);
  EXPECT_EQ(map->controls()[static_cast<size_t>(teeth)].follows, aa);
  EXPECT_EQ(map->controls()[static_cast<size_t>(teeth_mpb)].follows, mpb);
  EXPECT_FALSE(map->controls()[static_cast<size_t>(curl)].driven());
  // "aa": the open viseme, its teeth with it, the jaw's share on MouthOpen.
  auto w = Weights(*map, Viseme(face::OvrViseme::kAA, 12.5f));
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(aa)], 1);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(teeth)], 1);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(open)], 0.25f);  // 0.5 × 12.5 / 25
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(mpb)], 0);
  // B/P/M: lips closed, every opening shape shut even with the jaw open.
  w = Weights(*map, Viseme(face::OvrViseme::kPP, 12.5f));
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(mpb)], 1);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(teeth_mpb)], 1);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(open)], 0);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(aa)], 0);
  // Blinks are per eye (R = the character's right), expressions by tone.
  face::FaceFrame f;
  f.blink_left = 1;
  f.expression = face::Expression::kHappy;
  f.expression_weight = 0.5f;
  w = Weights(*map, f);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(blink_l)], 1);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(Find(*map, "h_expressions.ReyeClose_h"))], 0);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(smile)], 0.35f);
  // The morph weights: head and teeth meshes, every target of each.
  ASSERT_EQ(map->morph_meshes().size(), 2u);
  EXPECT_EQ(map->morph_meshes()[0].name, "H_DDS_HighRes");
  EXPECT_EQ(map->morph_meshes()[0].num_targets, 65);
  EXPECT_EQ(map->morph_meshes()[1].name, "h_TeethDown");
  EXPECT_EQ(map->num_morph_weights(), 65 + 31);
  std::vector<float> morphs(static_cast<size_t>(map->num_morph_weights()));
  map->MorphWeights(Weights(*map, Viseme(face::OvrViseme::kAA)), morphs);
  EXPECT_FLOAT_EQ(morphs[0], 1);        // h_expressions.AE_AA_h
  EXPECT_FLOAT_EQ(morphs[65 + 12], 1);  // h_teeth.t_AE_AA_h
}

// A vowel's mouth opens as far as the speech's jaw does: at half the
// speaker's wide opening, half the shape; the lips' own shapes (B/P/M, F/V)
// and a file's frames without a jaw are drawn at their weights.
TEST(FaceMap, VowelsOpenAsFarAsTheJaw) {
  const Rig man = LoadRig("characters/valid_white_m_1_casual.glb");
  auto map = FaceMap::Create(man);
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_DOUBLE_EQ(map->vowel_open_deg(), face::kSmplxJawSpeechWideDeg);
  const int aa = Find(*map, "h_expressions.AE_AA_h"), teeth = Find(*map, "h_teeth.t_AE_AA_h"),
            ow = Find(*map, "h_expressions.UW_U_h"), fv = Find(*map, "h_expressions.FV_h");
  for (int c : {aa, teeth, ow, fv}) ASSERT_GE(c, 0);
  const float half = static_cast<float>(face::kSmplxJawSpeechWideDeg / 2);
  auto w = Weights(*map, Viseme(face::OvrViseme::kAA, half));
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(aa)], 0.5f);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(teeth)], 0.5f);
  const float ow_full = Weights(*map, Viseme(face::OvrViseme::kOU, 2 * half))[static_cast<size_t>(ow)];
  EXPECT_GT(ow_full, 0.5f);
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kOU, half))[static_cast<size_t>(ow)], 0.5f * ow_full);
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kAA, 0))[static_cast<size_t>(aa)], 0);
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kAA, -1))[static_cast<size_t>(aa)], 0);
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kFF, 0))[static_cast<size_t>(fv)], 1);
  face::FaceFrame unknown = Viseme(face::OvrViseme::kAA, 0);
  unknown.jaw_known = false;
  EXPECT_FLOAT_EQ(Weights(*map, unknown)[static_cast<size_t>(aa)], 1);
  // A map file turns it off (0) or sets the opening.
  FaceMapOptions o;
  o.map_json = R"({"vowel_open_deg": 0})";
  map = FaceMap::Create(man, o);
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kAA, 0))[static_cast<size_t>(aa)], 1);
  o.map_json = R"({"vowel_open_deg": 10})";
  map = FaceMap::Create(man, o);
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kAA, 2.5f))[static_cast<size_t>(aa)], 0.25f);
}

TEST(FaceMap, GodetteVrm0PresetsResolveToTheirBinds) {
  const Rig godette = LoadRig("characters/godette.vrm");
  auto map = FaceMap::Create(godette);
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_EQ(map->mouth_family(), "vrm0");
  const int a = Find(*map, "a"), blink = Find(*map, "blink"), blink_l = Find(*map, "blink_l"), joy = Find(*map, "joy"),
            fun = Find(*map, "fun"), ah = Find(*map, "ah", "FaceMesh");
  for (int c : {a, blink, blink_l, joy, fun, ah}) ASSERT_GE(c, 0);
  EXPECT_EQ(map->controls()[static_cast<size_t>(a)].kind, FaceControlKind::kVrmExpression);
  EXPECT_EQ(map->controls()[static_cast<size_t>(a)].vmc_name, "A");
  EXPECT_EQ(map->controls()[static_cast<size_t>(blink_l)].vmc_name, "Blink_L");
  EXPECT_TRUE(map->controls()[static_cast<size_t>(blink_l)].binary);
  EXPECT_FALSE(map->controls()[static_cast<size_t>(blink)].driven());  // blink_l / blink_r are
  EXPECT_FALSE(map->controls()[static_cast<size_t>(fun)].driven());
  EXPECT_FALSE(map->controls()[static_cast<size_t>(ah)].driven());  // bound by the driven "a"
  // OVR "aa" -> A (and the table's share of the others); B/P/M closes it.
  auto w = Weights(*map, Viseme(face::OvrViseme::kAA));
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(a)], 1);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(Find(*map, "i"))], 0);
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kSS))[static_cast<size_t>(Find(*map, "i"))], 0.6f);
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kPP))[static_cast<size_t>(a)], 0);
  // "a" binds FaceMesh target 5 ("ah") at 100 %; joy binds oh 50 % + look_up 25 %.
  ASSERT_EQ(map->morph_meshes().size(), 1u);
  EXPECT_EQ(map->morph_meshes()[0].name, "FaceMesh");
  std::vector<float> morphs(static_cast<size_t>(map->num_morph_weights()));
  map->MorphWeights(w, morphs);
  EXPECT_FLOAT_EQ(morphs[5], 1);
  face::FaceFrame happy;
  happy.expression = face::Expression::kHappy;
  happy.expression_weight = 1;
  happy.blink_left = 0.6f;  // binary: closed
  map->MorphWeights(Weights(*map, happy), morphs);
  EXPECT_FLOAT_EQ(morphs[9], 0.5f);
  EXPECT_FLOAT_EQ(morphs[10], 0.25f);
  EXPECT_FLOAT_EQ(morphs[3], 1);  // blink_left
  EXPECT_FLOAT_EQ(morphs[4], 0);
}

TEST(FaceMap, Vrm1ExpressionsByName) {
  const Rig vrm1 = LoadRig("characters/formats/vrm1_expressions_test.vrm");
  auto map = FaceMap::Create(vrm1);
  ASSERT_TRUE(map.ok()) << map.status();
  ASSERT_EQ(map->controls().size(), 2u);
  const int happy = Find(*map, "happy"), blink = Find(*map, "blink");
  ASSERT_GE(happy, 0);
  ASSERT_GE(blink, 0);
  EXPECT_EQ(map->controls()[static_cast<size_t>(happy)].family, "vrm1");
  EXPECT_EQ(map->controls()[static_cast<size_t>(happy)].vmc_name, "happy");
  EXPECT_TRUE(map->controls()[static_cast<size_t>(happy)].binary);
  face::FaceFrame f;
  f.blink_left = f.blink_right = 0.8f;
  f.expression = face::Expression::kHappy;
  f.expression_weight = 0.4f;  // below the binary threshold
  auto w = Weights(*map, f);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(blink)], 0.8f);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(happy)], 0);
  // Both are texture-transform expressions: no morph target to write into a
  // GLB (a VRM runtime applies them by name).
  EXPECT_TRUE(map->morph_meshes().empty());
  const nlohmann::json info = RigInfoJson(vrm1, *map);
  EXPECT_EQ(info["format"], "vrm1");
  EXPECT_EQ(info["vrm"]["spec_version"], "1.0");
  EXPECT_EQ(info["vrm"]["look_at"]["type"], "expression");
}

TEST(FaceMap, RobotExpressionMorphsByPlainName) {
  const Rig robot = LoadRig("characters/robot_expressive.glb");
  auto map = FaceMap::Create(robot);
  ASSERT_TRUE(map.ok()) << map.status();
  ASSERT_EQ(map->controls().size(), 3u);
  EXPECT_EQ(map->num_driven(), 3);
  EXPECT_EQ(map->mouth_family(), "");
  face::FaceFrame f;
  f.expression = face::Expression::kSurprised;
  f.expression_weight = 0.7f;
  auto w = Weights(*map, f);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(Find(*map, "Surprised"))], 0.7f);
  EXPECT_FLOAT_EQ(w[static_cast<size_t>(Find(*map, "Angry"))], 0);
}

TEST(FaceMap, MapFileOverridesAndErrorsNameTheKey) {
  const Rig robot = LoadRig("characters/robot_expressive.glb");
  FaceMapOptions o;
  o.map_source = "robot.json";
  o.map_json = R"({"controls": [{"morph": "Surprised", "drive": {"aa": 1, "jaw": 0.5}, "close_for_pp": true},
                                {"morph": "Sad", "drive": {}}]})";
  auto map = FaceMap::Create(robot, o);
  ASSERT_TRUE(map.ok()) << map.status();
  const int surprised = Find(*map, "Surprised");
  EXPECT_EQ(map->controls()[static_cast<size_t>(surprised)].family, "map");
  EXPECT_FALSE(map->controls()[static_cast<size_t>(Find(*map, "Sad"))].driven());
  EXPECT_TRUE(map->controls()[static_cast<size_t>(Find(*map, "Angry"))].driven());  // automatic kept
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kAA, 5))[static_cast<size_t>(surprised)], 1);
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kPP, 25))[static_cast<size_t>(surprised)], 0);
  // The jaw's scale: 2 deg is half open with jaw_full_open_deg 4.
  o.map_json = R"({"jaw_full_open_deg": 4, "controls": [{"morph": "Sad", "drive": {"jaw": 1}}]})";
  map = FaceMap::Create(robot, o);
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_FLOAT_EQ(Weights(*map, Viseme(face::OvrViseme::kAA, 2))[static_cast<size_t>(Find(*map, "Sad"))], 0.5f);
  o.map_json = R"({"automatic": false, "controls": [{"morph": "Angry", "drive": {"angry": 1}}]})";
  map = FaceMap::Create(robot, o);
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_EQ(map->num_driven(), 1);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {R"({"controls": [{"morph": "Nose", "drive": {"aa": 1}}]})", "robot.json: controls[0].morph"},
      {R"({"controls": [{"morph": "Sad", "drive": {"smile": 1}}]})", "robot.json: controls[0].drive.smile"},
      {R"({"controls": [{"morph": "Sad", "drive": {"aa": 1e9}}]})", "robot.json: controls[0].drive.aa"},
      {R"({"jaw_bone": "Jaw"})", "robot.json: jaw_bone"},
      {R"({"jaw_max_deg": 400})", "robot.json: jaw_max_deg"},
      {R"({"jaw_full_open_deg": 0})", "robot.json: jaw_full_open_deg"},
      {R"({"vowel_open_deg": 0.1})", "robot.json: vowel_open_deg"},
      {R"({"controls": {}})", "robot.json: controls"},
      {R"({"mouth": 1})", "robot.json: mouth"},
      {"[", "robot.json"}};
  for (const auto& [text, field] : bad) {
    o.map_json = text;
    auto r = FaceMap::Create(robot, o);
    ASSERT_FALSE(r.ok()) << text;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << text;
    EXPECT_EQ(r.status().message().rfind(field, 0), 0u) << text << " -> " << r.status();
  }
}

// SMPL-X has a jaw joint: the face turns it about its hinge (the head's
// left-right axis square to the jaw bone) and the chin goes down.
TEST(FaceMap, SmplxJawOpensAboutItsHinge) {
  auto clip = motion::ReadBvhFile(Data("paired/beat2/2_scott_0_2_2.bvh"));
  ASSERT_TRUE(clip.ok());
  auto rig = RigFromSkeleton(clip->skeleton, 0.01, "smplx");
  ASSERT_TRUE(rig.ok());
  auto map = FaceMap::Create(*rig);
  ASSERT_TRUE(map.ok()) << map.status();
  ASSERT_GE(map->jaw().joint, 0);
  EXPECT_EQ(map->jaw().name, "jaw");
  EXPECT_EQ(map->jaw().found_by, "role");
  // The hinge is left-right (x in SMPL-X's rest).
  EXPECT_GT(std::abs(map->jaw().hinge_axis.x()), 0.9) << map->jaw().hinge_axis.transpose();
  const motion::Skeleton& sk = rig->skeleton;
  std::vector<double> frame(static_cast<size_t>(sk.num_channels()), 0.0);
  std::vector<Eigen::Vector3d> pos(static_cast<size_t>(sk.num_joints()));
  std::vector<Eigen::Matrix3d> rot(pos.size());
  const int jaw = map->jaw().joint;
  auto chin = [&] {
    EXPECT_TRUE(motion::ComputeWorldPose(sk, frame, pos, rot).ok());
    const motion::Joint& j = sk.joint(jaw);
    return Eigen::Vector3d(pos[static_cast<size_t>(jaw)] + rot[static_cast<size_t>(jaw)] * j.end_site.value_or(Eigen::Vector3d(0, -5, 5)));
  };
  const Eigen::Vector3d closed = chin();
  ASSERT_TRUE(map->ApplyJaw(sk, 15, frame).ok());
  const Eigen::Vector3d open = chin();
  EXPECT_LT(open.y(), closed.y() - 0.5) << "cm: the chin goes down";
  EXPECT_NEAR(open.x(), closed.x(), 0.05);  // cm: about the (nearly) left-right axis
  // B/P/M close it; the opening is bounded.
  EXPECT_DOUBLE_EQ(map->JawAngleDeg(Viseme(face::OvrViseme::kPP, 20)), 0);
  EXPECT_DOUBLE_EQ(map->JawAngleDeg(Viseme(face::OvrViseme::kAA, 20)), 20);
  EXPECT_DOUBLE_EQ(map->JawAngleDeg(Viseme(face::OvrViseme::kAA, 80)), map->jaw().max_deg);
}

// The GLB carries the face: per driven mesh a `weights` channel whose output
// holds every target per frame (glTF's rule), read back by tinygltf.
TEST(FaceMap, GlbWritesMorphWeightsForEveryTarget) {
  const Rig man = LoadRig("characters/valid_white_m_1_casual.glb");
  auto map = FaceMap::Create(man);
  ASSERT_TRUE(map.ok());
  auto clip = motion::ReadBvhFile(Data("paired/beat2/2_scott_0_2_2.bvh"));
  ASSERT_TRUE(clip.ok());
  clip->frames.conservativeResize(60, clip->frames.cols());
  auto out = RetargetClip(*clip, 0.01, man);
  ASSERT_TRUE(out.ok());
  face::FaceTrack track;  // aa, PP, aa ... every 5 frames
  for (int f = 0; f < 60; ++f) {
    track.frames.push_back(Viseme((f / 5) % 2 ? face::OvrViseme::kPP : face::OvrViseme::kAA, 10));
    track.frames.back().time_s = f * track.frame_time_s;
  }
  auto face = SampleFace(*map, track, out->clip.num_frames(), out->clip.frame_time_s);
  ASSERT_TRUE(face.ok()) << face.status();
  GlbWriteOptions w;
  w.face_map = &*map;
  w.face = &*face;
  const std::string path = (std::filesystem::temp_directory_path() / "kinemo_face_test.glb").string();
  ASSERT_TRUE(WriteAnimatedGlb(man, out->clip, path, w).ok());
  auto back = ReadGltf(path);
  std::filesystem::remove(path);
  ASSERT_TRUE(back.ok()) << back.status();
  const tinygltf::Model& m = (*back)->model;
  EXPECT_TRUE((*back)->decoded.empty());  // written decoded
  ASSERT_FALSE(m.animations.empty());
  const tinygltf::Animation& anim = m.animations[0];
  int weight_channels = 0;
  for (const auto& ch : anim.channels) {
    if (ch.target_path != "weights") continue;
    ++weight_channels;
    const tinygltf::Node& node = m.nodes[static_cast<size_t>(ch.target_node)];
    const size_t targets = m.meshes[static_cast<size_t>(node.mesh)].primitives[0].targets.size();
    const tinygltf::AnimationSampler& s = anim.samplers[static_cast<size_t>(ch.sampler)];
    EXPECT_EQ(m.accessors[static_cast<size_t>(s.output)].count, 60 * targets) << node.name;
    EXPECT_EQ(m.accessors[static_cast<size_t>(s.input)].count, 60u);
  }
  EXPECT_EQ(weight_channels, 2);  // head and lower teeth
  // The image sources: PNG fallbacks beside the WebP ones.
  int png = 0;
  for (const auto& img : m.images) png += img.mimeType == "image/png";
  EXPECT_EQ(png, 2);
  EXPECT_EQ(std::count(m.extensionsRequired.begin(), m.extensionsRequired.end(), "EXT_texture_webp"), 0);
  EXPECT_EQ(std::count(m.extensionsUsed.begin(), m.extensionsUsed.end(), "EXT_texture_webp"), 1);
}

}  // namespace
}  // namespace kinemo::retarget
