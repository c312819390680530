#include "services/coordinator/demo/vleo_demo.h"

#include <chrono>
#include <filesystem>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "common/server/service_host.h"
#include "kinemo/cube_tracker/v1/options.pb.h"
#include "kinemo/robot_bridge/v1/options.pb.h"
#include "services/coordinator/demo/pleo_sim_child.h"
#include "services/coordinator/coordinator_service.h"
#include "services/cube_tracker/core/cube_model.h"
#include "services/cube_tracker/cube_tracker_service.h"
#include "services/cube_tracker/render/renderer.h"
#include "services/robot_bridge/robot_bridge_service.h"

namespace kinemo::coordinator {
namespace {

namespace fs = std::filesystem;
namespace rb = ::kinemo::robot_bridge::v1;

StatusOr<std::unique_ptr<server::ServiceHost>> Serve(std::shared_ptr<grpc::Service> s,
                                                     const std::string& name,
                                                     const std::string& full_name) {
  common::v1::ServerOptions o;
  o.set_host("127.0.0.1");
  o.set_port(0);
  o.set_shutdown_grace_s(0.2);
  o.set_log_level("warn");
  return server::ServiceHost::Start(o, name, {{std::move(s), full_name}});
}

}  // namespace

StatusOr<VleoDemoResult> RunVleoDemo(const VleoDemoOptions& o,
                                     const std::function<void(const v1::SessionEvent&)>& on_event) {
  VleoDemoResult out;
  // 1. Render the scripted cube video (and the camera it was seen with).
  std::string dir = o.work_dir;
  if (dir.empty()) {
    char tmpl[] = "/tmp/kinemo-vleo-XXXXXX";
    if (::mkdtemp(tmpl) == nullptr) return absl::InternalError("mkdtemp failed");
    dir = tmpl;
  }
  fs::create_directories(dir);
  KINEMO_ASSIGN_OR_RETURN(auto model, cube::LoadCubeModel(o.cube_model));
  KINEMO_ASSIGN_OR_RETURN(auto script, cube::LoadRenderScript(o.script));
  out.video = dir + "/vleo_scenario.avi";
  const std::string camera = dir + "/vleo_scenario_camera.yml";
  KINEMO_RETURN_IF_ERROR(cube::SequenceRenderer::RenderToFiles(model, script, out.video,
                                                              dir + "/vleo_scenario_truth.json",
                                                              camera));
  // 2. pleo_sim, robot bridge, cube tracker, coordinator.
  PleoSimChild sim;
  KINEMO_ASSIGN_OR_RETURN(const int sim_port, sim.Start(o.pleo_sim));
  rb::RobotBridgeOptions bo;
  auto* robot = bo.add_robots();
  robot->set_robot_id("pleo");
  robot->mutable_tcp()->set_host("127.0.0.1");
  robot->mutable_tcp()->set_port(sim_port);
  KINEMO_ASSIGN_OR_RETURN(auto bridge, robot_bridge::RobotBridgeServiceImpl::Create(bo));
  KINEMO_ASSIGN_OR_RETURN(auto bridge_host,
                          Serve(bridge, "demo_bridge", rb::RobotBridgeService::service_full_name()));
  cube_tracker::v1::CubeTrackerOptions to;
  to.set_file_root(fs::absolute(dir).string());  // the rendered video and camera only
  KINEMO_ASSIGN_OR_RETURN(auto tracker, cube_tracker::CubeTrackerService::Create(to));
  KINEMO_ASSIGN_OR_RETURN(
      auto tracker_host,
      Serve(tracker, "demo_cube_tracker", cube_tracker::v1::CubeTrackerService::service_full_name()));
  v1::CoordinatorOptions co;
  co.mutable_services()->mutable_robot_bridge()->set_address(bridge_host->address());
  co.mutable_services()->mutable_cube_tracker()->set_address(tracker_host->address());
  co.mutable_emotion()->set_rate_per_s(o.rate_per_s);
  KINEMO_ASSIGN_OR_RETURN(auto coordinator, CoordinatorServiceImpl::Create(co));
  KINEMO_ASSIGN_OR_RETURN(
      auto host, Serve(coordinator, "demo_coordinator", v1::CoordinatorService::service_full_name()));
  auto stub = v1::CoordinatorService::NewStub(
      grpc::CreateChannel(host->address(), grpc::InsecureChannelCredentials()));

  // 3. A cube session; watch it; attach the video (played in real time). The
  // surface comes from the rendered camera file (as `kinemo cube calibrate
  // --surface` would write it).
  v1::OpenSessionRequest open;
  open.set_session_id("vleo");
  open.set_robot_id("pleo");
  open.set_vleo(v1::VLEO_KIND_CUBE);
  open.set_vleo_name("scripted cube");
  open.set_initial_emotion(o.initial);
  v1::OpenSessionResponse opened;
  {
    grpc::ClientContext ctx;
    grpc::Status s = stub->OpenSession(&ctx, open, &opened);
    if (!s.ok()) return absl::UnavailableError(absl::StrCat("OpenSession: ", s.error_message()));
  }
  grpc::ClientContext watch;
  v1::WatchSessionRequest w;
  w.set_session_id("vleo");
  auto reader = stub->WatchSession(&watch, w);
  v1::AttachCubeRequest attach;
  attach.set_session_id("vleo");
  attach.mutable_source()->set_video_file(fs::absolute(out.video).string());
  attach.mutable_source()->set_realtime(true);
  *attach.mutable_config()->mutable_cube_model() = cube::CubeModelToProto(model);
  attach.mutable_config()->set_intrinsics_file(fs::absolute(camera).string());
  {
    grpc::ClientContext ctx;
    v1::AttachCubeResponse r;
    grpc::Status s = stub->AttachCube(&ctx, attach, &r);
    if (!s.ok()) return absl::UnavailableError(absl::StrCat("AttachCube: ", s.error_message()));
  }
  v1::SessionEvent e;
  while (reader->Read(&e)) {
    on_event(e);
    if (e.has_cube_status_changed() && !e.cube_status_changed().attached()) break;
  }
  watch.TryCancel();
  (void)reader->Finish();
  // 4. The final state: the model's, and what pleo_sim shows (read through the bridge).
  {
    grpc::ClientContext ctx;
    v1::GetSessionRequest g;
    g.set_session_id("vleo");
    v1::Session s;
    if (stub->GetSession(&ctx, g, &s).ok()) out.final_emotion = s.emotion();
  }
  auto bstub = rb::RobotBridgeService::NewStub(
      grpc::CreateChannel(bridge_host->address(), grpc::InsecureChannelCredentials()));
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (std::chrono::steady_clock::now() < until) {
    grpc::ClientContext ctx;
    rb::GetStatusRequest g;
    g.set_robot_id("pleo");
    rb::RobotStatus st;
    if (bstub->GetStatus(&ctx, g, &st).ok()) {
      out.robot_shows = st.shown_emotion();
      if (st.shown_emotion() == out.final_emotion && st.state() == rb::ROBOT_STATE_FOLLOWING) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  host->Shutdown();
  coordinator->Stop();
  tracker_host->Shutdown();
  bridge_host->Shutdown();
  return out;
}

}  // namespace kinemo::coordinator
