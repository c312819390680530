// kinemo_vmc: the normalized humanoid of real motion capture (BEAT2 SMPL-X,
// Bandai, CMU), its names, the face's blend shapes, the OSC datagrams
// (decoded with liblo) and their way over a loopback UDP socket.
#include <arpa/inet.h>
#include <lo/lo.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "common/motion/bvh.h"
#include "common/motion/kinematics.h"
#include "common/retarget/face_map.h"
#include "common/retarget/gltf.h"
#include "common/vmc/blend.h"
#include "common/vmc/humanoid.h"
#include "common/vmc/osc.h"
#include "common/vmc/vmc_stream.h"
#include "gtest/gtest.h"

namespace kinemo::vmc {
namespace {

using retarget::roles::Finger;
using retarget::roles::Side;

std::string Data(const std::string& rel) { return std::string(KINEMO_TEST_DATA_DIR) + "/" + rel; }

motion::Clip ReadClip(const std::string& rel, int max_frames = 300) {
  auto clip = motion::ReadBvhFile(Data(rel));
  EXPECT_TRUE(clip.ok()) << clip.status();
  if (clip->num_frames() > max_frames) clip->frames.conservativeResize(max_frames, Eigen::NoChange);
  return *std::move(clip);
}

// Forward kinematics on the humanoid as a receiver does it (Unity axes):
// world positions of every bone.
std::vector<Eigen::Vector3d> HumanoidFk(std::span<const HumanoidBone> bones, const HumanoidPose& pose) {
  std::vector<Eigen::Vector3d> pos(bones.size());
  std::vector<Eigen::Quaterniond> rot(bones.size());
  for (size_t i = 0; i < bones.size(); ++i) {
    const int p = bones[i].parent;
    if (p < 0) {
      pos[i] = pose.hips_position_m;
      rot[i] = pose.local_rotation[i];
    } else {
      pos[i] = pos[p] + rot[p] * bones[i].local_position_m;
      rot[i] = rot[p] * pose.local_rotation[i];
    }
  }
  return pos;
}

// The humanoid's bones sit where the source's joints are (U · C · p · m) in
// every frame: forward kinematics of the VMC pose reproduces the motion.
// With `whole_body` false, only each bone relative to its parent, for the
// bones whose source joint hangs directly under the parent's (elsewhere a
// source joint between two roles, such as CMU's upper neck, turns what the
// humanoid cannot: it keeps the rest offsets).
void ExpectFkFollowsSource(const motion::Clip& clip, const HumanoidOptions& options, double tolerance_m,
                           bool whole_body, int min_bones_checked) {
  auto poser = HumanoidPoser::Create(clip.skeleton, options);
  ASSERT_TRUE(poser.ok()) << poser.status();
  std::vector<Eigen::Vector3d> sp(clip.skeleton.num_joints());
  std::vector<Eigen::Matrix3d> sr(clip.skeleton.num_joints());
  HumanoidPose pose;
  const auto bones = poser->bones();
  std::vector<bool> check(bones.size(), whole_body);
  for (size_t i = 1; i < bones.size() && !whole_body; ++i) {
    const motion::Joint& j = clip.skeleton.joint(bones[i].source_joint);
    check[i] = j.parent == bones[bones[i].parent].source_joint;
  }
  EXPECT_GE(std::count(check.begin(), check.end(), true), min_bones_checked);
  const Eigen::Matrix3d u = poser->unity_from_source() * poser->meters_per_unit();
  double worst = 0;
  for (int f = 0; f < clip.num_frames(); ++f) {
    ASSERT_TRUE(poser->Pose(clip.frame(f), &pose).ok());
    ASSERT_TRUE(motion::ComputeWorldPose(clip.skeleton, clip.frame(f), sp, sr).ok());
    const auto fk = HumanoidFk(bones, pose);
    for (size_t i = 0; i < fk.size(); ++i) {
      if (!check[i]) continue;
      const Eigen::Vector3d want = whole_body ? Eigen::Vector3d(u * sp[bones[i].source_joint])
                                              : Eigen::Vector3d(u * (sp[bones[i].source_joint] - sp[bones[bones[i].parent].source_joint]));
      const Eigen::Vector3d got = whole_body ? fk[i] : Eigen::Vector3d(fk[i] - fk[bones[i].parent]);
      worst = std::max(worst, (got - want).norm());
    }
  }
  EXPECT_LT(worst, tolerance_m);
}

TEST(VmcNames, UnityAndVrm1) {
  EXPECT_EQ(BoneName(retarget::roles::kHips, BoneNaming::kUnity), "Hips");
  EXPECT_EQ(BoneName(retarget::roles::kUpperChest, BoneNaming::kUnity), "UpperChest");
  EXPECT_EQ(BoneName(Side(0, retarget::roles::kForearm), BoneNaming::kUnity), "LeftLowerArm");
  EXPECT_EQ(BoneName(Side(1, retarget::roles::kThigh), BoneNaming::kUnity), "RightUpperLeg");
  EXPECT_EQ(BoneName(Finger(0, 0, 0), BoneNaming::kUnity), "LeftThumbProximal");
  EXPECT_EQ(BoneName(Finger(1, 4, 2), BoneNaming::kUnity), "RightLittleDistal");
  EXPECT_EQ(BoneName(retarget::roles::kUpperChest, BoneNaming::kVrm1), "upperChest");
  EXPECT_EQ(BoneName(Finger(0, 0, 0), BoneNaming::kVrm1), "leftThumbMetacarpal");
  EXPECT_EQ(BoneName(Finger(0, 0, 1), BoneNaming::kVrm1), "leftThumbProximal");
  EXPECT_EQ(BoneName(Finger(1, 1, 1), BoneNaming::kVrm1), "rightIndexIntermediate");
  EXPECT_EQ(BoneName(Side(1, retarget::roles::kToes), BoneNaming::kVrm1), "rightToes");
  EXPECT_FALSE(ParseBoneNaming("vrm0", "--vmc-bones").ok());
  EXPECT_EQ(*ParseBoneNaming("vrm1", "--vmc-bones"), BoneNaming::kVrm1);
}

TEST(VmcHumanoid, Beat2SmplxFollowsTheSourceExactly) {
  const motion::Clip clip = ReadClip("paired/beat2/2_scott_0_2_2.bvh");
  ExpectFkFollowsSource(clip, {}, 1e-9, /*whole_body=*/true, 53);
  auto poser = HumanoidPoser::Create(clip.skeleton);
  ASSERT_TRUE(poser.ok());
  EXPECT_DOUBLE_EQ(poser->meters_per_unit(), 0.01);  // BEAT2 files are in cm
  // Every role of the SMPL-X tree: 7 core (hips .. jaw) + 2 × (8 + 15).
  EXPECT_EQ(poser->bones().size(), 53u);
  // Reflection: right-handed file axes -> Unity's left-handed.
  EXPECT_NEAR(poser->unity_from_source().determinant(), -1, 1e-12);
}

TEST(VmcHumanoid, RestIsTheVrmTPose) {
  const motion::Clip clip = ReadClip("paired/beat2/2_scott_0_2_2.bvh", 1);
  auto poser = HumanoidPoser::Create(clip.skeleton);
  ASSERT_TRUE(poser.ok());
  std::map<std::string, Eigen::Vector3d> offset;
  for (const HumanoidBone& b : poser->bones()) {
    offset[std::string(BoneName(b.role, BoneNaming::kUnity))] = b.local_position_m.normalized();
  }
  auto near = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return (a - b).norm() < 1e-9; };
  // Unity: the character faces +Z, its left is -X. Arms, hands, fingers
  // along the arm; thumbs level at 45° forward; legs straight down.
  for (const char* b : {"LeftLowerArm", "LeftHand", "LeftMiddleProximal", "LeftIndexIntermediate"}) {
    EXPECT_TRUE(near(offset[b], {-1, 0, 0})) << b << " " << offset[b].transpose();
  }
  for (const char* b : {"RightLowerArm", "RightHand", "RightMiddleProximal", "RightRingDistal"}) {
    EXPECT_TRUE(near(offset[b], {1, 0, 0})) << b << " " << offset[b].transpose();
  }
  EXPECT_TRUE(near(offset["LeftThumbIntermediate"], Eigen::Vector3d(-1, 0, 1).normalized()));
  EXPECT_TRUE(near(offset["RightThumbDistal"], Eigen::Vector3d(1, 0, 1).normalized()));
  for (const char* b : {"LeftLowerLeg", "LeftFoot", "RightLowerLeg", "RightFoot"}) {
    EXPECT_TRUE(near(offset[b], {0, -1, 0})) << b << " " << offset[b].transpose();
  }
  // Feet straight forward (the source's pitch kept), the head above the neck.
  EXPECT_NEAR(offset["LeftToes"].x(), 0, 1e-9);
  EXPECT_GT(offset["LeftToes"].z(), 0.5);
  EXPECT_GT(offset["Head"].y(), 0.9);
  EXPECT_LT(offset["LeftUpperLeg"].x(), 0);  // the left hip on the character's left (-X)
  EXPECT_LT(offset["LeftShoulder"].x(), 0);
  // SMPL-X's own rest is close to a T-pose: the trunk and head turn little
  // to reach it, the arms (which hang ~19° below the T, elbows bent ~24°)
  // and the feet (toes out ~20°) more (local rotations of the source's rest:
  // all channels zero).
  std::vector<double> rest(static_cast<size_t>(clip.skeleton.num_channels()), 0.0);
  HumanoidPose pose;
  ASSERT_TRUE(poser->Pose(rest, &pose).ok());
  std::map<std::string, double> deg;
  for (size_t i = 0; i < poser->bones().size(); ++i) {
    deg[std::string(BoneName(poser->bones()[i].role, BoneNaming::kUnity))] =
        2 * std::acos(std::min(1.0, std::abs(pose.local_rotation[i].w()))) * 180 / M_PI;
  }
  for (const char* b : {"Hips", "Spine", "Chest", "UpperChest", "Neck", "Head"}) EXPECT_LT(deg[b], 5) << b;
  for (const char* b : {"LeftUpperArm", "RightUpperArm", "LeftLowerArm", "RightLowerArm", "LeftFoot", "RightFoot"}) {
    EXPECT_GT(deg[b], 3) << b;
    EXPECT_LT(deg[b], 30) << b;
  }
}

TEST(VmcHumanoid, OtherFamiliesFollowTheirSource) {
  // Bandai (no fingers, a joint_Root above the hips, the zero pose lying
  // along +x, position channels on every joint, which hold the offsets to
  // 1e-5 cm) and CMU cgspeed (an upper neck between neck and head, finger
  // stubs not mapped): each bone turns as the source's does.
  ExpectFkFollowsSource(ReadClip("motion/131_01.bvh", 120), {}, 1e-9, /*whole_body=*/false, 14);
  ExpectFkFollowsSource(ReadClip("motion/cmu_002_03.bvh", 120), {}, 1e-9, /*whole_body=*/false, 14);
  ExpectFkFollowsSource(ReadClip("motion/dataset-1_bye_normal_001.bvh", 120), {}, 1e-6, /*whole_body=*/false, 20);
  // CMU cgspeed: hips, lowerback, Chest, Chest2, lowerneck, Head and 8 per
  // side; Bandai: no upper chest, no jaw, no fingers.
  EXPECT_EQ(HumanoidPoser::Create(ReadClip("motion/131_01.bvh", 1).skeleton)->bones().size(), 22u);
  EXPECT_EQ(HumanoidPoser::Create(ReadClip("motion/dataset-1_bye_normal_001.bvh", 1).skeleton)->bones().size(), 21u);
  HumanoidOptions no_fingers;
  no_fingers.fingers = false;
  auto poser = HumanoidPoser::Create(ReadClip("paired/beat2/2_scott_0_2_2.bvh", 1).skeleton, no_fingers);
  ASSERT_TRUE(poser.ok());
  EXPECT_EQ(poser->bones().size(), 23u);
}

// The mouth and expression a VRM app receives over VMC are the ones a VRM
// rig gets from kinemo's face map (one recipe table): on Godette (VRM 0.x,
// tests/data/characters), for every OVR viseme alone, B/P/M over a vowel and
// each expression, VMC's A I U E O Joy Angry Sorrow equal the face map's
// a i u e o joy angry sorrow (Godette has no surprised clip). Consonants open the vowel shapes
// by the table's share (DD: A 0.3), B/P/M closes them, blinks split into the
// closure both eyes share and each eye's remainder.
TEST(VmcBlend, FaceToVrmPresetsAsTheRigGetsThem) {
  auto rig = retarget::LoadGltfRig(Data("characters/godette.vrm"));
  ASSERT_TRUE(rig.ok()) << rig.status();
  auto map = retarget::FaceMap::Create(*rig);
  ASSERT_TRUE(map.ok()) << map.status();
  const auto& v0 = BlendShapeNames(BlendNaming::kVrm0);
  const auto& v1 = BlendShapeNames(BlendNaming::kVrm1);
  const std::map<std::string, std::string> rig_name = {{"A", "a"},     {"I", "i"},         {"U", "u"},
                                                       {"E", "e"},     {"O", "o"},         {"Joy", "joy"},
                                                       {"Angry", "angry"}, {"Sorrow", "sorrow"}};  // Godette has no surprised
  std::vector<face::FaceFrame> frames;
  for (int v = 0; v < face::kNumOvrVisemes; ++v) {
    face::FaceFrame f;
    f.ovr[static_cast<size_t>(v)] = 0.8f;
    frames.push_back(f);
  }
  face::FaceFrame closing;  // lips pressed while an "aa" fades
  closing.ovr[static_cast<int>(face::OvrViseme::kAA)] = 0.5f;
  closing.ovr[static_cast<int>(face::OvrViseme::kPP)] = 0.6f;
  frames.push_back(closing);
  for (face::Expression e : {face::Expression::kHappy, face::Expression::kAngry, face::Expression::kSad,
                             face::Expression::kSurprised}) {
    face::FaceFrame f;
    f.expression = e;
    f.expression_weight = 0.7f;
    frames.push_back(f);
  }
  std::vector<float> rig_w(map->controls().size());
  int compared = 0;
  for (const face::FaceFrame& f : frames) {
    const BlendWeights w = FaceBlendWeights(f);
    map->Weights(f, rig_w);
    for (int k = 0; k < kNumBlendShapes; ++k) {
      const auto it = rig_name.find(std::string(v0[static_cast<size_t>(k)]));
      if (it == rig_name.end()) continue;
      int c = -1;
      for (size_t i = 0; i < map->controls().size(); ++i)
        if (map->controls()[i].name == it->second) c = static_cast<int>(i);
      ASSERT_GE(c, 0) << it->second;
      EXPECT_FLOAT_EQ(w[static_cast<size_t>(k)], rig_w[static_cast<size_t>(c)]) << v0[static_cast<size_t>(k)];
      ++compared;
    }
  }
  EXPECT_EQ(compared, 8 * static_cast<int>(frames.size()));

  face::FaceFrame f;
  f.ovr[static_cast<int>(face::OvrViseme::kDD)] = 1.0f;  // a consonant opens "a" by the table's 0.3
  std::map<std::string_view, float> by0, by1;
  auto fill = [&](const face::FaceFrame& x) {
    const BlendWeights w = FaceBlendWeights(x);
    for (int k = 0; k < kNumBlendShapes; ++k) {
      by0[v0[static_cast<size_t>(k)]] = w[static_cast<size_t>(k)];
      by1[v1[static_cast<size_t>(k)]] = w[static_cast<size_t>(k)];
    }
  };
  fill(f);
  EXPECT_FLOAT_EQ(by0["A"], 0.3f);
  EXPECT_FLOAT_EQ(by1["aa"], 0.3f);
  EXPECT_FLOAT_EQ(by0["I"], 0.3f);
  f = face::FaceFrame{};
  f.ovr[static_cast<int>(face::OvrViseme::kAA)] = 1.0f;
  f.ovr[static_cast<int>(face::OvrViseme::kPP)] = 1.0f;  // lips pressed: every vowel shape shut
  f.blink_left = 0.8f;
  f.blink_right = 0.5f;
  f.expression = face::Expression::kSad;
  f.expression_weight = 0.7f;
  fill(f);
  EXPECT_FLOAT_EQ(by0["A"], 0.0f);
  EXPECT_FLOAT_EQ(by0["Blink"], 0.5f);
  EXPECT_FLOAT_EQ(by0["Blink_L"], 0.3f);
  EXPECT_FLOAT_EQ(by1["blinkRight"], 0.0f);
  EXPECT_FLOAT_EQ(by0["Sorrow"], 0.7f);
  EXPECT_FLOAT_EQ(by1["sad"], 0.7f);
  EXPECT_FLOAT_EQ(by1["happy"], 0.0f);
  EXPECT_FLOAT_EQ(by0["Fun"], 0.0f);
  EXPECT_EQ(v0[11], "Fun");
  EXPECT_EQ(v1[11], "relaxed");
}

TEST(VmcOsc, EndpointsAndLoopback) {
  auto e = ParseEndpoint("39539", "--vmc");
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->host, "127.0.0.1");
  EXPECT_EQ(e->port, 39539);
  e = ParseEndpoint("[::1]:5000", "--vmc");
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->host, "::1");
  e = ParseEndpoint("studio.local:39540", "--vmc");
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->host, "studio.local");
  for (const char* bad : {"", ":5000", "host:0", "host:70000", "host:x", "::1:5000", "[::1]5000", "host:", "[[x]:50",
                          "a[b:5", "a]b:5"}) {
    const auto s = ParseEndpoint(bad, "--vmc");
    EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    if (!s.ok()) {
      EXPECT_TRUE(std::string(s.status().message()).starts_with("--vmc: ")) << s.status();
    }
  }
  EXPECT_TRUE(*IsLoopbackHost("127.0.0.1", "x"));
  EXPECT_TRUE(*IsLoopbackHost("127.3.2.1", "x"));
  EXPECT_TRUE(*IsLoopbackHost("::1", "x"));
  EXPECT_FALSE(*IsLoopbackHost("192.0.2.7", "x"));  // TEST-NET-1
  auto refused = UdpSender::Open({"192.0.2.7", 39539}, /*loopback_only=*/true, "config.vmc.address");
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kPermissionDenied);
  EXPECT_TRUE(std::string(refused.status().message()).starts_with("config.vmc.address: ")) << refused.status();
}

// The messages of a datagram, decoded by liblo: (address, type tags, args).
struct Decoded {
  std::string address, types;
  std::vector<std::string> strings;
  std::vector<float> floats;
  std::vector<int> ints;
};
std::vector<Decoded> DecodeBundle(const std::string& d) {
  std::vector<Decoded> out;
  EXPECT_GE(d.size(), 16u);
  EXPECT_EQ(std::memcmp(d.data(), "#bundle\0", 8), 0);
  size_t at = 16;
  while (at + 4 <= d.size()) {
    uint32_t n;
    std::memcpy(&n, d.data() + at, 4);
    n = ntohl(n);
    at += 4;
    EXPECT_LE(at + n, d.size());
    int result = 0;
    lo_message m = lo_message_deserialise(const_cast<char*>(d.data() + at), n, &result);
    EXPECT_NE(m, nullptr) << result;
    if (m == nullptr) return out;
    Decoded dec;
    dec.address = d.data() + at;
    dec.types = lo_message_get_types(m);
    lo_arg** argv = lo_message_get_argv(m);
    for (size_t k = 0; k < dec.types.size(); ++k) {
      if (dec.types[k] == 's') dec.strings.emplace_back(&argv[k]->s);
      if (dec.types[k] == 'f') dec.floats.push_back(argv[k]->f);
      if (dec.types[k] == 'i') dec.ints.push_back(argv[k]->i);
    }
    lo_message_free(m);
    out.push_back(std::move(dec));
    at += n;
  }
  EXPECT_EQ(at, d.size());
  return out;
}

TEST(VmcStream, FramesOverLoopbackUdp) {
  const motion::Clip clip = ReadClip("paired/beat2/2_scott_0_2_2.bvh", 12);
  // A receiving socket on an ephemeral loopback port.
  const int rx = ::socket(AF_INET, SOCK_DGRAM, 0);
  ASSERT_GE(rx, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(rx, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  socklen_t len = sizeof addr;
  ASSERT_EQ(::getsockname(rx, reinterpret_cast<sockaddr*>(&addr), &len), 0);
  auto sender = UdpSender::Open({"127.0.0.1", ntohs(addr.sin_port)}, true, "--vmc");
  ASSERT_TRUE(sender.ok()) << sender.status();
  VmcStreamOptions o;
  o.fps = 15;  // every other frame of 30
  VmcStream stream(*std::move(sender), o);
  EXPECT_EQ(stream.SendFrame(0, clip.frame(0), nullptr).status().code(), absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(stream.Start(clip.skeleton).ok());
  face::FaceFrame face;
  face.ovr[static_cast<int>(face::OvrViseme::kOU)] = 1;
  face.jaw_open_deg = static_cast<float>(face::kSmplxJawSpeechWideDeg);  // the vowel drawn fully open
  int sent = 0;
  for (int f = 0; f < clip.num_frames(); ++f) {
    auto s = stream.SendFrame(f * clip.frame_time_s, clip.frame(f), f % 4 == 0 ? &face : nullptr);
    ASSERT_TRUE(s.ok()) << s.status();
    sent += *s ? 1 : 0;
  }
  EXPECT_EQ(sent, 6);
  EXPECT_EQ(stream.stats().frames, 6u);
  EXPECT_EQ(stream.stats().bones, 53u);
  EXPECT_EQ(stream.stats().blendshapes, 13u);
  EXPECT_EQ(stream.stats().dropped, 0u);
  // Read every datagram back and decode it.
  std::map<std::string, int> bone_messages;
  int blend = 0, apply = 0, ok = 0, times = 0, roots = 0;
  std::vector<float> t_values;
  for (uint64_t k = 0; k < stream.stats().packets; ++k) {
    pollfd p{rx, POLLIN, 0};
    ASSERT_EQ(::poll(&p, 1, 2000), 1);
    std::string buf(65536, '\0');
    const ssize_t n = ::recv(rx, buf.data(), buf.size(), 0);
    ASSERT_GT(n, 0);
    buf.resize(static_cast<size_t>(n));
    EXPECT_LE(buf.size(), kDefaultMaxDatagramBytes);
    for (const Decoded& m : DecodeBundle(buf)) {
      if (m.address == "/VMC/Ext/Bone/Pos") {
        ASSERT_EQ(m.types, "sfffffff");
        ++bone_messages[m.strings[0]];
        const double qn = std::hypot(std::hypot(m.floats[3], m.floats[4]), std::hypot(m.floats[5], m.floats[6]));
        EXPECT_NEAR(qn, 1, 1e-5);
      } else if (m.address == "/VMC/Ext/Root/Pos") {
        EXPECT_EQ(m.types, "sfffffff");
        EXPECT_EQ(m.strings[0], "root");
        ++roots;
      } else if (m.address == "/VMC/Ext/Blend/Val") {
        EXPECT_EQ(m.types, "sf");
        if (m.strings[0] == "U") {
          EXPECT_FLOAT_EQ(m.floats[0], 1.0f);
        }
        ++blend;
      } else if (m.address == "/VMC/Ext/Blend/Apply") {
        EXPECT_EQ(m.types, "");
        ++apply;
      } else if (m.address == "/VMC/Ext/OK") {
        EXPECT_EQ(m.types, "i");
        EXPECT_EQ(m.ints[0], 1);
        ++ok;
      } else if (m.address == "/VMC/Ext/T") {
        EXPECT_EQ(m.types, "f");
        t_values.push_back(m.floats[0]);
        ++times;
      } else {
        ADD_FAILURE() << m.address;
      }
    }
  }
  ::close(rx);
  EXPECT_EQ(roots, 6);
  EXPECT_EQ(ok, 6);
  EXPECT_EQ(times, 6);
  EXPECT_EQ(bone_messages.size(), 53u);
  for (const auto& [name, count] : bone_messages) EXPECT_EQ(count, 6) << name;
  EXPECT_EQ(blend, 3 * 13);  // frames 0, 4, 8 carry a face
  EXPECT_EQ(apply, 3);
  ASSERT_EQ(t_values.size(), 6u);
  for (size_t k = 0; k < t_values.size(); ++k) EXPECT_NEAR(t_values[k], 2 * k * clip.frame_time_s, 1e-5);
  EXPECT_GT(stream.stats().packets, 6u);  // 53 bones do not fit one 1452-byte datagram
}

TEST(VmcStream, Options) {
  VmcStreamOptions o;
  o.fps = 300;
  EXPECT_EQ(ValidateVmcOptions(o, "--vmc-fps").code(), absl::StatusCode::kInvalidArgument);
  o.fps = -1;
  EXPECT_FALSE(ValidateVmcOptions(o, "--vmc-fps").ok());
  o.fps = 60;
  EXPECT_TRUE(ValidateVmcOptions(o, "--vmc-fps").ok());
}

}  // namespace
}  // namespace kinemo::vmc
