// In-process tests of the planner's locomotion RPCs on real motion capture:
// BuildLocomotionGraph, PlanTransition, EvaluateLocomotion, Drive, errors.
#include <gtest/gtest.h>

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cmath>

#include "common/motion/bvh.h"
#include "common/server/service_host.h"
#include "services/planner/rpc/planner_service.h"

namespace kinemo::planner {
namespace {

// CMU subject 131 trial 1 ("start walk stop", 31 joints, 120 fps): its first
// 1.7 s of standing is sent as the idle clip, 2.2 s of its walking as the
// walk clip (inline clips, cut from the real file).
constexpr const char* kIdle = "idle";
constexpr const char* kWalk = "walk";

std::string Slice(const motion::Clip& full, int first, int last) {
  motion::Clip c = full;
  c.frames = full.frames.middleRows(first, last - first).eval();
  return *motion::WriteBvh(c);
}

class LocomotionServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    v1::PlannerOptions o;
    o.set_library_root(KINEMO_TEST_DATA_DIR);
    o.set_drive_tick_s(0.1);
    auto svc = PlannerServiceImpl::Create(o);
    ASSERT_TRUE(svc.ok()) << svc.status();
    common::v1::ServerOptions so;
    so.set_host("127.0.0.1");
    so.set_port(0);
    so.set_shutdown_grace_s(1);
    auto host = server::ServiceHost::Start(so, "planner-locomotion-test", {{*svc, v1::PlannerService::service_full_name()}});
    ASSERT_TRUE(host.ok()) << host.status();
    host_ = *std::move(host);
    stub_ = v1::PlannerService::NewStub(host_->InProcessChannel());
    v1::LoadLibraryRequest lreq;
    lreq.set_library_id("avatar");
    auto full = motion::ReadBvhFile(std::string(KINEMO_TEST_DATA_DIR) + "/motion/131_01.bvh");
    ASSERT_TRUE(full.ok()) << full.status();
    auto* idle = lreq.add_clips();
    idle->set_name(kIdle);
    idle->set_bvh(Slice(*full, 0, 200));
    auto* walk = lreq.add_clips();
    walk->set_name(kWalk);
    walk->set_bvh(Slice(*full, 520, 780));
    v1::LoadLibraryResponse lres;
    auto ctx = Ctx();
    ASSERT_TRUE(stub_->LoadLibrary(ctx.get(), lreq, &lres).ok());
  }
  void TearDown() override { host_->Shutdown(); }

  std::unique_ptr<grpc::ClientContext> Ctx(int seconds = 60) {
    auto c = std::make_unique<grpc::ClientContext>();
    c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
    return c;
  }

  grpc::Status Build(const std::string& id, const std::string& profile, double threshold, bool overwrite,
                     v1::BuildLocomotionGraphResponse* res) {
    v1::BuildLocomotionGraphRequest req;
    req.set_graph_id(id);
    req.set_library_id("avatar");
    req.mutable_profile()->set_name(profile);
    req.mutable_params()->set_threshold(threshold);
    req.set_overwrite(overwrite);
    auto ctx = Ctx();
    return stub_->BuildLocomotionGraph(ctx.get(), req, res);
  }

  std::unique_ptr<server::ServiceHost> host_;
  std::unique_ptr<v1::PlannerService::Stub> stub_;
};

TEST_F(LocomotionServiceTest, BuildPlanEvaluate) {
  v1::BuildLocomotionGraphResponse built;
  ASSERT_TRUE(Build("g", "SP2", 0.4, false, &built).ok());
  const auto& info = built.graph();
  EXPECT_EQ(info.graph_id(), "g");
  EXPECT_EQ(info.version(), 1u);
  ASSERT_EQ(info.parts_size(), 2);
  EXPECT_EQ(info.parts(0).part().chains(0), v1::KINEMATIC_CHAIN_LOWER);
  EXPECT_EQ(info.params().progressive_window_frames(), 20u);  // 10 frames at 60 fps = 20 at 120 fps
  EXPECT_GT(info.connectivity(), 0);
  EXPECT_GT(info.build_s_per_clip_minute(), 0);
  double share = 0;
  for (const auto& p : info.parts()) share += p.threshold();
  EXPECT_NEAR(share, 0.4, 1e-9);
  // Building again needs overwrite.
  v1::BuildLocomotionGraphResponse again;
  EXPECT_EQ(Build("g", "SP2", 0.4, false, &again).error_code(), grpc::StatusCode::ALREADY_EXISTS);
  ASSERT_TRUE(Build("g", "SP2", 0.4, true, &again).ok());
  EXPECT_EQ(again.graph().version(), 2u);

  // A transition walk -> idle with motion as BVH.
  v1::PlanTransitionRequest preq;
  preq.set_graph_id("g");
  preq.set_from_clip(kWalk);
  preq.set_to_clip(kIdle);
  preq.set_format(common::v1::MOTION_FORMAT_BVH);
  v1::PlanTransitionResponse pres;
  grpc::Status st;
  for (uint32_t f = 0; f < 250; f += 3) {
    preq.set_from_frame(f);
    pres.Clear();
    auto ctx = Ctx();
    st = stub_->PlanTransition(ctx.get(), preq, &pres);
    if (st.ok()) break;
    EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND) << st.error_message();
  }
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(pres.paths_size(), 2);
  EXPECT_GE(pres.tbf_frames(), pres.response_frames());
  EXPECT_GT(pres.search_us(), 0);
  auto clip = motion::ParseBvh(pres.motion().bvh(), "transition");
  ASSERT_TRUE(clip.ok()) << clip.status();
  EXPECT_EQ(clip->num_frames(), static_cast<int>(pres.tbf_frames()) + 1);
  EXPECT_EQ(clip->skeleton.num_joints(), 31);
  const int channels = clip->skeleton.num_channels();
  // Structured clip form.
  preq.set_format(common::v1::MOTION_FORMAT_CLIP);
  {
    auto ctx = Ctx();
    ASSERT_TRUE(stub_->PlanTransition(ctx.get(), preq, &pres).ok());
    ASSERT_GT(pres.motion().clip().frames_size(), 0);
    EXPECT_EQ(pres.motion().clip().frames(0).values_size(), channels);
  }
  // Errors name the field.
  preq.set_from_frame(100000);
  {
    auto ctx = Ctx();
    st = stub_->PlanTransition(ctx.get(), preq, &pres);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(st.error_message().find("from_frame"), std::string::npos);
  }
  preq.set_graph_id("nope");
  {
    auto ctx = Ctx();
    EXPECT_EQ(stub_->PlanTransition(ctx.get(), preq, &pres).error_code(), grpc::StatusCode::NOT_FOUND);
  }

  // Evaluation rows.
  v1::EvaluateLocomotionRequest ereq;
  ereq.set_library_id("avatar");
  ereq.add_profiles()->set_name("SMG");
  ereq.add_profiles()->set_name("SP2");
  ereq.add_thresholds(0.2);
  ereq.add_thresholds(0.4);
  ereq.set_include_maneuverability(true);
  v1::EvaluateLocomotionResponse eres;
  {
    auto ctx = Ctx(300);
    st = stub_->EvaluateLocomotion(ctx.get(), ereq, &eres);
  }
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(eres.clips_size(), 2);
  EXPECT_NEAR(eres.frame_rate_hz(), 120, 0.1);
  ASSERT_EQ(eres.rows_size(), 4);
  EXPECT_EQ(eres.rows(0).method(), "SMG");
  EXPECT_EQ(eres.rows(2).method(), "SP2");
  EXPECT_EQ(eres.rows(3).maneuverability_size(), 4);
  EXPECT_GT(eres.rows(1).connected_clips(), 0u);
  // A bad profile is refused, naming it.
  ereq.add_profiles()->set_name("SP7");
  {
    auto ctx = Ctx();
    st = stub_->EvaluateLocomotion(ctx.get(), ereq, &eres);
  }
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("profiles[2]"), std::string::npos) << st.error_message();
}

TEST_F(LocomotionServiceTest, DriveWalksToTheTarget) {
  v1::BuildLocomotionGraphResponse built;
  ASSERT_TRUE(Build("g", "SP2", 0.4, false, &built).ok());
  auto ctx = Ctx(60);
  auto stream = stub_->Drive(ctx.get());
  v1::DriveRequest req;
  auto* cfg = req.mutable_config();
  cfg->set_graph_id("g");
  cfg->set_idle_clip(kIdle);
  cfg->set_walk_clip(kWalk);
  ASSERT_TRUE(stream->Write(req));
  req.Clear();
  req.set_cube_angle_deg(60);  // 'Speed' 2.88: walk
  ASSERT_TRUE(stream->Write(req));
  req.Clear();
  req.mutable_target_m()->set_x(1.0);
  req.mutable_target_m()->set_y(0.0);
  ASSERT_TRUE(stream->Write(req));
  v1::DriveResponse res;
  ASSERT_TRUE(stream->Read(&res));
  ASSERT_TRUE(res.has_header());
  int channels = 0;
  for (const auto& j : res.header().skeleton().joints()) channels += j.channels_size();
  EXPECT_NEAR(res.header().frame_time_s(), 1.0 / 120, 1e-5);
  bool reached = false, walked = false;
  int batches = 0;
  double last_time = -1;
  while (batches < 100 && stream->Read(&res)) {
    ++batches;
    ASSERT_TRUE(res.has_frames());
    EXPECT_EQ(res.frames().frames_size(), 12);  // 0.1 s ticks at 120 fps
    for (const auto& f : res.frames().frames()) {
      EXPECT_EQ(f.values_size(), channels);
      EXPECT_GT(f.time_s(), last_time);
      last_time = f.time_s();
    }
    walked = walked || res.status().state() == v1::LOCOMOTION_STATE_WALK;
    if (res.status().target_reached()) {
      reached = true;
      break;
    }
  }
  EXPECT_TRUE(walked);
  EXPECT_TRUE(reached);
  stream->WritesDone();
  while (stream->Read(&res)) {
  }
  const grpc::Status fin = stream->Finish();
  EXPECT_TRUE(fin.ok()) << fin.error_code() << " " << fin.error_message();
}

TEST_F(LocomotionServiceTest, DriveRefusesAStreamWithoutConfig) {
  auto ctx = Ctx(30);
  auto stream = stub_->Drive(ctx.get());
  v1::DriveRequest req;
  req.set_speed(2);
  stream->Write(req);
  stream->WritesDone();
  v1::DriveResponse res;
  while (stream->Read(&res)) {
  }
  const grpc::Status st = stream->Finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(st.error_message().find("config"), std::string::npos);
}

}  // namespace
}  // namespace kinemo::planner
