// kinemo_allinone with cubes and durable sessions, with the real binary on one
// store_dir: AttachCube used to abort the process (SIGABRT: the in-process
// channel is not a client channel, issue 16); a source that cannot be opened
// is now answered up front with the tracker's error; a cube sent with
// ConfigureCube, the sessions and a running cube attachment all survive a
// restart, and the attachment re-subscribes.
#include <gtest/gtest.h>

#include <grpcpp/grpcpp.h>

#include "absl/strings/match.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "tests/integration/stores/cube_video.h"
#include "tests/integration/stores/stores_fixture.h"

namespace kinemo::stores_test {
namespace {

namespace cv1 = ::kinemo::coordinator::v1;
namespace ct = ::kinemo::cube_tracker::v1;
using testing::ServiceProcess;
using namespace std::chrono_literals;

std::unique_ptr<grpc::ClientContext> Ctx(std::chrono::seconds timeout = 30s) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + timeout);
  return c;
}

grpc::Status Attach(cv1::CoordinatorService::Stub& stub, const std::string& video, bool realtime,
                    cv1::AttachCubeResponse* out) {
  cv1::AttachCubeRequest r;
  r.set_session_id("desk");
  r.mutable_source()->set_video_file(video);
  r.mutable_source()->set_realtime(realtime);
  r.mutable_config()->set_cube_id("vleo");
  return stub.AttachCube(Ctx().get(), r, out);
}

// Reads the session's events until the cube detaches; its reason.
std::string WaitForDetach(cv1::CoordinatorService::Stub& stub, int* cube_actions) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 60s);
  cv1::WatchSessionRequest w;
  w.set_session_id("desk");
  auto reader = stub.WatchSession(&ctx, w);
  cv1::SessionEvent e;
  std::string reason = "(no detach)";
  while (reader->Read(&e)) {
    if (e.has_action_changed() && e.action_changed().from_cube()) ++*cube_actions;
    if (e.has_cube_status_changed() && !e.cube_status_changed().attached()) {
      reason = e.cube_status_changed().reason();
      break;
    }
  }
  ctx.TryCancel();
  (void)reader->Finish();
  return reason;
}

TEST(AllInOne, CubesAttachWithoutAbortAndSessionsSurviveARestart) {
  testing::TempDir dir;
  auto video = RenderCubeVideo(kData, dir);
  ASSERT_TRUE(video.ok()) << video.status();
  // No cube in the options: the tracker knows the cube only from ConfigureCube.
  std::ofstream(dir.File("allinone.textproto"))
      << "store_dir: \"" << dir.File("store") << "\"\n"
      << "seed_store_dir: \"" << dir.File("no-seed") << "\"\n"
      << "cube_tracker { file_root: \"" << dir.path() << "\" default_intrinsics_file: \""
      << dir.File("camera.yaml") << "\" }\n";
  const testing::ServiceProcessOptions options{.binary = Binary("kinemo_allinone"),
                                               .args = {"--config", dir.File("allinone.textproto")},
                                               .health_service = cv1::CoordinatorService::service_full_name()};
  {
    auto stack = ServiceProcess::Start(options);
    ASSERT_TRUE(stack.ok()) << stack.status();
    auto tracker = ct::CubeTrackerService::NewStub((*stack)->Channel());
    ct::ConfigureCubeRequest configure;
    *configure.mutable_model() = cube::CubeModelToProto(video->model);
    ct::ConfigureCubeResponse configured;
    const grpc::Status c = tracker->ConfigureCube(Ctx().get(), configure, &configured);
    ASSERT_TRUE(c.ok()) << c.error_message();
    ASSERT_EQ(configured.model().cube_id(), "vleo");

    auto stub = cv1::CoordinatorService::NewStub((*stack)->Channel());
    cv1::OpenSessionRequest open;
    open.set_session_id("desk");
    open.set_robot_id("pleo");
    cv1::OpenSessionResponse opened;
    ASSERT_TRUE(stub->OpenSession(Ctx().get(), open, &opened).ok());

    // Sources that cannot be opened: the tracker's error, up front.
    cv1::AttachCubeResponse attached;
    grpc::Status s = Attach(*stub, "missing.avi", false, &attached);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "source.video_file")) << s.error_message();
    s = Attach(*stub, "truth.json", false, &attached);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
    EXPECT_TRUE(absl::StartsWith(s.error_message(), "source.video_file")) << s.error_message();
    ASSERT_TRUE((*stack)->process().Running()) << (*stack)->process().ReadLog();
    cv1::Session session;
    cv1::GetSessionRequest get;
    get.set_session_id("desk");
    ASSERT_TRUE(stub->GetSession(Ctx().get(), get, &session).ok());
    EXPECT_FALSE(session.cube_attached());

    // A real video, as fast as it decodes: attached, drives the session, ends.
    s = Attach(*stub, "seq.avi", false, &attached);
    ASSERT_TRUE(s.ok()) << s.error_message() << (*stack)->process().ReadLog();
    EXPECT_TRUE(attached.session().cube_attached());
    // The first tracked frame's face is the attach's state (the face the
    // video starts on, before any turn).
    EXPECT_TRUE(attached.session().cube_visible());
    EXPECT_EQ(attached.session().cube_face(), cube::FaceToProto(video->script.initial_top_face));
    int actions = 0;
    EXPECT_EQ(WaitForDetach(*stub, &actions), "source ended");
    EXPECT_GT(actions, 0);

    // At the file's rate: still attached when the process stops.
    ASSERT_TRUE(Attach(*stub, "seq.avi", true, &attached).ok());
    auto code = (*stack)->Stop();
    ASSERT_TRUE(code.ok());
    EXPECT_EQ(*code, 0);
  }
  auto stack = ServiceProcess::Start(options);
  ASSERT_TRUE(stack.ok()) << stack.status();
  // The cube from ConfigureCube is in the all-in-one's store.
  auto tracker = ct::CubeTrackerService::NewStub((*stack)->Channel());
  common::v1::ListArtifactsRequest list;
  list.set_kind("cubes");
  common::v1::ListArtifactsResponse cubes;
  ASSERT_TRUE(tracker->ListArtifacts(Ctx().get(), list, &cubes).ok());
  ASSERT_EQ(cubes.artifacts_size(), 1);
  EXPECT_EQ(cubes.artifacts(0).ref().id(), "vleo");
  // The session is back, its cube re-subscribed: it runs to the video's end.
  auto stub = cv1::CoordinatorService::NewStub((*stack)->Channel());
  cv1::Session session;
  cv1::GetSessionRequest get;
  get.set_session_id("desk");
  ASSERT_TRUE(stub->GetSession(Ctx().get(), get, &session).ok());
  EXPECT_EQ(session.vleo(), cv1::VLEO_KIND_CUBE);
  EXPECT_TRUE(session.cube_attached());
  int actions = 0;
  EXPECT_EQ(WaitForDetach(*stub, &actions), "source ended");
  EXPECT_GT(actions, 0);
  ASSERT_TRUE(stub->GetSession(Ctx().get(), get, &session).ok());
  EXPECT_FALSE(session.cube_attached());
}

}  // namespace
}  // namespace kinemo::stores_test
