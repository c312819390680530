// A rig is a stored artifact ("rigs", owned by the planner): pushed, listed,
// deleted; Animate and StreamAnimate with models.rig_id answer on its
// skeleton; an unknown id is NOT_FOUND naming the request's field; a file
// that is no rig is refused naming the pushed file.
#include <chrono>
#include <fstream>
#include <set>
#include <sstream>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <tuple>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "common/motion/bvh.h"
#include "common/retarget/rig.h"
#include "services/coordinator/client/live_client.h"
#include "services/coordinator/coordinator_service.h"
#include "tests/service/coordinator/live_stack.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
namespace cv1 = ::kinemo::common::v1;
const std::string kSpeech = kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";
const std::string kMan = kData + "/characters/quaternius_man_casual.glb";

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::unique_ptr<grpc::ClientContext> Ctx(int seconds = 120) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  return c;
}

// One file pushed in one chunk.
grpc::Status PushRig(planner::v1::PlannerService::Stub* stub, const std::string& id, const std::string& name,
                     const std::string& bytes, cv1::PushArtifactResponse* response) {
  auto ctx = Ctx();
  auto writer = stub->PushArtifact(ctx.get(), response);
  cv1::PushArtifactRequest header;
  header.mutable_header()->mutable_ref()->set_kind("rigs");
  header.mutable_header()->mutable_ref()->set_id(id);
  auto* f = header.mutable_header()->add_files();
  f->set_name(name);
  f->set_size_bytes(bytes.size());
  cv1::PushArtifactRequest chunk;
  chunk.mutable_chunk()->set_file_index(0);
  chunk.mutable_chunk()->set_data(bytes);
  if (writer->Write(header) && writer->Write(chunk)) writer->WritesDone();
  return writer->Finish();
}

struct Coordinator {
  std::shared_ptr<CoordinatorServiceImpl> service;
  std::unique_ptr<server::ServiceHost> host;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<v1::CoordinatorService::Stub> stub;
  Coordinator() {
    auto in_process = LiveStack::Get().services->InProcessChannel();
    v1::CoordinatorOptions o;
    o.mutable_animate()->mutable_models()->set_inference_model_id("crf");
    o.mutable_animate()->mutable_models()->set_controller_id("ctrl");
    auto c = CoordinatorServiceImpl::Create(o, {in_process, in_process, in_process, nullptr, nullptr});
    EXPECT_TRUE(c.ok()) << c.status();
    service = *c;
    host = Host({{service, v1::CoordinatorService::service_full_name()}});
    channel = grpc::CreateChannel(host->address(), grpc::InsecureChannelCredentials());
    stub = v1::CoordinatorService::NewStub(channel);
  }
  ~Coordinator() {
    host->Shutdown();
    service->Stop();
  }
};

class RigLive : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!LiveStack::Get().error.empty()) GTEST_FAIL() << "live stack: " << LiveStack::Get().error;
    planner_ = planner::v1::PlannerService::NewStub(
        grpc::CreateChannel(LiveStack::Get().services->address(), grpc::InsecureChannelCredentials()));
    auto man = retarget::LoadGltfRig(kMan);
    ASSERT_TRUE(man.ok()) << man.status();
    man_ = *std::move(man);
  }
  v1::AnimateRequest Request(const std::string& rig_id) const {
    v1::AnimateRequest req;
    req.mutable_audio()->mutable_format()->set_encoding(cv1::AUDIO_ENCODING_FILE);
    req.mutable_audio()->set_data(ReadFile(kSpeech));
    req.mutable_models()->set_rig_id(rig_id);
    req.set_format(cv1::MOTION_FORMAT_BVH);
    return req;
  }
  std::unique_ptr<planner::v1::PlannerService::Stub> planner_;
  retarget::Rig man_;
};

TEST_F(RigLive, AnimateAndStreamAnimateAnswerOnAStoredRig) {
  cv1::PushArtifactResponse pushed;
  grpc::Status s = PushRig(planner_.get(), "man", "Quaternius_Man.glb", ReadFile(kMan), &pushed);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(pushed.artifact().ref().kind(), "rigs");
  EXPECT_EQ(pushed.artifact().ref().version(), 1u);
  EXPECT_TRUE(absl::StrContains(pushed.artifact().summary_json(), "left_upper_arm")) << pushed.artifact().summary_json();
  {
    cv1::ListArtifactsRequest list;
    list.set_kind("rigs");
    cv1::ListArtifactsResponse listed;
    ASSERT_TRUE(planner_->ListArtifacts(Ctx().get(), list, &listed).ok());
    ASSERT_EQ(listed.artifacts_size(), 1);
    EXPECT_EQ(listed.artifacts(0).ref().id(), "man");
    ASSERT_EQ(pushed.artifact().files_size(), 1);
    EXPECT_EQ(pushed.artifact().files(0).name(), "rig.glb");
  }

  Coordinator co;
  // Animate: BVH on the man's skeleton (its joints, in its bind pose), the
  // same length as on the library's own skeleton.
  v1::AnimateResponse own, on_rig;
  ASSERT_TRUE(co.stub->Animate(Ctx().get(), Request(""), &own).ok());
  s = co.stub->Animate(Ctx().get(), Request("man"), &on_rig);
  ASSERT_TRUE(s.ok()) << s.error_message();
  auto own_clip = motion::ParseBvh(own.motion().bvh(), "own");
  auto rig_clip = motion::ParseBvh(on_rig.motion().bvh(), "rig");
  ASSERT_TRUE(own_clip.ok() && rig_clip.ok());
  // (BVH lists the joints depth first: the same joints, in another order.)
  ASSERT_EQ(rig_clip->skeleton.num_joints(), man_.skeleton.num_joints());
  std::set<std::string> bvh_names, rig_names;
  for (int j = 0; j < man_.skeleton.num_joints(); ++j) {
    bvh_names.insert(rig_clip->skeleton.joint(j).name);
    rig_names.insert(man_.skeleton.joint(j).name);
  }
  EXPECT_EQ(bvh_names, rig_names);
  EXPECT_NE(own_clip->skeleton.joint(0).name, rig_clip->skeleton.joint(0).name);
  EXPECT_EQ(rig_clip->num_frames(), own_clip->num_frames());
  // The man's arms move (the upper arm's rotation channels vary).
  const int man_arm = man_.roles.joint[retarget::roles::Side(0, retarget::roles::kUpperArm)];
  ASSERT_GE(man_arm, 0);
  const int arm = rig_clip->skeleton.FindJoint(man_.skeleton.joint(man_arm).name);
  ASSERT_GE(arm, 0);
  const int arm_channel = rig_clip->skeleton.joint(arm).first_channel + 1;
  double lo = 1e9, hi = -1e9;
  for (int f = 0; f < rig_clip->num_frames(); ++f) {
    lo = std::min(lo, rig_clip->frame(f)[static_cast<size_t>(arm_channel)]);
    hi = std::max(hi, rig_clip->frame(f)[static_cast<size_t>(arm_channel)]);
  }
  EXPECT_GT(hi - lo, 2.0) << "left upper arm, degrees";

  // StreamAnimate: the header is the rig's skeleton, each frame its channels.
  auto audio = audio::DecodeAudioFile(kSpeech);
  ASSERT_TRUE(audio.ok());
  LiveStreamOptions lo_opts;
  lo_opts.realtime = false;
  lo_opts.config.mutable_models()->set_rig_id("man");
  auto live = RunLiveStream(co.channel, audio->samples, audio->sample_rate_hz, lo_opts);
  ASSERT_TRUE(live.ok()) << live.status();
  ASSERT_EQ(live->header.skeleton().joints_size(), man_.skeleton.num_joints());
  EXPECT_EQ(live->header.skeleton().joints(0).name(), man_.skeleton.joint(0).name);
  EXPECT_EQ(live->header.skeleton().name(), "rig:man");
  ASSERT_GT(live->frames.size(), 100u);
  for (const auto& f : live->frames) ASSERT_EQ(f.values_size(), man_.skeleton.num_channels());

  // Unknown ids: NOT_FOUND naming the request's field, in both calls.
  v1::AnimateResponse none;
  s = co.stub->Animate(Ctx().get(), Request("nobody"), &none);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(absl::StrContains(s.error_message(), "models.rig_id")) << s.error_message();
  lo_opts.config.mutable_models()->set_rig_id("nobody");
  auto missing = RunLiveStream(co.channel, audio->samples, audio->sample_rate_hz, lo_opts);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(absl::StrContains(missing.status().message(), "config.models.rig_id")) << missing.status();

  // Deleted: the id is gone again.
  cv1::DeleteArtifactRequest del;
  del.mutable_ref()->set_kind("rigs");
  del.mutable_ref()->set_id("man");
  cv1::DeleteArtifactResponse deleted;
  ASSERT_TRUE(planner_->DeleteArtifact(Ctx().get(), del, &deleted).ok());
  s = co.stub->Animate(Ctx().get(), Request("man"), &none);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
}

// The characters with faces push as rigs: the VALID man (meshopt-compressed,
// quantized), Godette (VRM 0.x), the VRM 1.0 test humanoid; their summaries
// say the format and how many face channels kinemo drives. A damaged
// compressed file is refused naming the pushed file and the part.
TEST_F(RigLive, CompressedAndVrmCharactersPush) {
  const std::vector<std::tuple<std::string, std::string, std::string, int>> rigs = {
      {"valid-man", "/characters/valid_white_m_1_casual.glb", "\"format\":\"glb\"", 40},
      {"godette", "/characters/godette.vrm", "\"format\":\"vrm0\"", 8},
      {"vrm1", "/characters/formats/vrm1_expressions_test.vrm", "\"format\":\"vrm1\"", 2}};
  for (const auto& [id, file, format, driven] : rigs) {
    cv1::PushArtifactResponse pushed;
    const std::string name = file.substr(file.rfind('/') + 1);
    grpc::Status s = PushRig(planner_.get(), id, name, ReadFile(kData + file), &pushed);
    ASSERT_TRUE(s.ok()) << id << ": " << s.error_message();
    const auto summary = nlohmann::json::parse(pushed.artifact().summary_json());
    EXPECT_TRUE(absl::StrContains(pushed.artifact().summary_json(), format)) << pushed.artifact().summary_json();
    EXPECT_GE(summary["face_channels_driven"].get<int>(), driven) << id;
    EXPECT_GT(summary["leg_length_m"].get<double>(), 0.35) << id;
  }
  std::string damaged = ReadFile(kData + "/characters/valid_white_m_1_casual.glb");
  damaged.resize(damaged.size() - 4096);
  cv1::PushArtifactResponse pushed;
  grpc::Status s = PushRig(planner_.get(), "broken", "broken.glb", damaged, &pushed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "header.files[0]")) << s.error_message();
  EXPECT_TRUE(absl::StrContains(s.error_message(), "broken.glb")) << s.error_message();
}

TEST_F(RigLive, AFileThatIsNoRigIsRefusedNamingIt) {
  cv1::PushArtifactResponse pushed;
  // A BVH under a .glb name: not glTF.
  grpc::Status s = PushRig(planner_.get(), "fake", "fake.glb",
                           ReadFile(kData + "/motion/dataset-1_bye_normal_001.bvh"), &pushed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "header.files[0]")) << s.error_message();
  // Not a .glb / .vrm.
  s = PushRig(planner_.get(), "fake", "man.bvh", ReadFile(kMan), &pushed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(absl::StartsWith(s.error_message(), "header.files")) << s.error_message();
  cv1::ListArtifactsRequest list;
  list.set_kind("rigs");
  cv1::ListArtifactsResponse listed;
  ASSERT_TRUE(planner_->ListArtifacts(Ctx().get(), list, &listed).ok());
  for (const auto& a : listed.artifacts()) EXPECT_NE(a.ref().id(), "fake");
}

}  // namespace
}  // namespace kinemo::coordinator
