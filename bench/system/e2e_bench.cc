#include "bench/system/e2e_bench.h"
#include "services/coordinator/demo/pleo_sim_child.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "common/audio/decode.h"
#include "common/server/service_host.h"
#include "kinemo/robot_bridge/v1/options.pb.h"
#include "services/coordinator/client/live_client.h"
#include "services/coordinator/coordinator_service.h"
#include "services/robot_bridge/robot_bridge_service.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
using SteadyClock = std::chrono::steady_clock;

double Ms(SteadyClock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

std::unique_ptr<server::ServiceHost> Serve(std::shared_ptr<grpc::Service> s, const std::string& name,
                                           const std::string& full_name, Status* error) {
  common::v1::ServerOptions o;
  o.set_host("127.0.0.1");
  o.set_port(0);
  o.set_shutdown_grace_s(0.2);
  auto h = server::ServiceHost::Start(o, name, {{std::move(s), full_name}});
  if (!h.ok()) {
    *error = h.status();
    return nullptr;
  }
  return std::move(*h);
}

// StreamAnimate at real-time pace, measured on the client's clock.
Status MeasureAudio(const E2eBenchOptions& o, E2eBenchResult* out) {
  auto audio = audio::DecodeAudioFile(o.speech_file);
  if (!audio.ok()) return audio.status();
  LiveStreamOptions lo;
  lo.realtime = true;
  lo.config.mutable_models()->set_inference_model_id(o.model_id);
  lo.config.mutable_models()->set_controller_id(o.controller_id);
  lo.config.set_request_id("bench-e2e");
  KINEMO_ASSIGN_OR_RETURN(auto credentials, MakeChannelCredentials(o.coordinator_tls));
  KINEMO_ASSIGN_OR_RETURN(
      LiveStreamResult r,
      RunLiveStream(grpc::CreateChannel(o.coordinator, credentials), audio->samples, audio->sample_rate_hz, lo));
  out->speech_s = r.audio_s;
  out->audio_to_frame_p50_ms = r.audio_to_frame_p50_ms;
  out->audio_to_frame_p99_ms = r.audio_to_frame_p99_ms;
  out->motion_lag_p50_ms = r.motion_lag_p50_ms;
  out->motion_lag_p99_ms = r.motion_lag_p99_ms;
  out->first_frame_ms = r.first_frame_ms;
  out->max_frame_gap_ms = r.max_frame_gap_ms;
  out->max_chunk_late_ms = r.max_chunk_late_ms;
  return absl::OkStatus();
}

}  // namespace

StatusOr<E2eBenchResult> RunE2eBench(const E2eBenchOptions& o) {
  E2eBenchResult out;
  PleoSimChild sim;
  KINEMO_ASSIGN_OR_RETURN(const int sim_port, sim.Start(o.pleo_sim));

  robot_bridge::v1::RobotBridgeOptions bo;
  auto* robot = bo.add_robots();
  robot->set_robot_id("pleo");
  robot->mutable_tcp()->set_host("127.0.0.1");
  robot->mutable_tcp()->set_port(sim_port);
  KINEMO_ASSIGN_OR_RETURN(auto bridge, robot_bridge::RobotBridgeServiceImpl::Create(bo));
  Status error;
  auto bridge_host = Serve(bridge, "bench_bridge",
                           robot_bridge::v1::RobotBridgeService::service_full_name(), &error);
  if (!bridge_host) return error;

  v1::CoordinatorOptions co;
  co.mutable_services()->mutable_robot_bridge()->set_address(bridge_host->address());
  // A fast model: an action flips angry <-> happy within 0.15 ms of model
  // time, so the measurement is the path, not the model's (by design slow)
  // rate.
  co.mutable_emotion()->set_rate_per_s(10000);
  co.set_max_sessions(std::max(o.sessions + 10, 10000));
  KINEMO_ASSIGN_OR_RETURN(auto coordinator, CoordinatorServiceImpl::Create(co));
  auto host = Serve(coordinator, "bench_coordinator", v1::CoordinatorService::service_full_name(),
                    &error);
  if (!host) return error;
  auto stub = v1::CoordinatorService::NewStub(
      grpc::CreateChannel(host->address(), grpc::InsecureChannelCredentials()));

  // 1. Act -> register written (acknowledged), seen by a watching client.
  {
    v1::OpenSessionRequest open;
    open.set_session_id("bench");
    open.set_robot_id("pleo");
    open.set_initial_emotion(common::v1::EMOTION_ANGRY);
    v1::OpenSessionResponse opened;
    grpc::ClientContext c;
    grpc::Status s = stub->OpenSession(&c, open, &opened);
    if (!s.ok()) return absl::UnavailableError(absl::StrCat("OpenSession: ", s.error_message()));
    grpc::ClientContext wctx;
    v1::WatchSessionRequest w;
    w.set_session_id("bench");
    auto reader = stub->WatchSession(&wctx, w);
    v1::SessionEvent e;
    // Until the initial emotion is on the robot (it may be before the snapshot).
    while (reader->Read(&e)) {
      if (e.has_snapshot() && e.snapshot().robot_emotion() == common::v1::EMOTION_ANGRY) break;
      if (e.has_robot_commanded() && e.robot_commanded().error().empty()) break;
      if (e.has_robot_status_changed() &&
          e.robot_status_changed().shown_emotion() == common::v1::EMOTION_ANGRY) {
        break;
      }
    }
    std::vector<double> e2e, bridge_ms;
    for (int i = 0; i < o.actions + 10; ++i) {
      const bool kiss = i % 2 == 0;
      const auto want = kiss ? common::v1::EMOTION_HAPPY : common::v1::EMOTION_ANGRY;
      v1::ActRequest act;
      act.set_session_id("bench");
      act.set_action(kiss ? common::v1::ACTION_KISSES : common::v1::ACTION_SHOUTING);
      act.set_intensity(1.0);
      v1::ActResponse acted;
      const auto t0 = SteadyClock::now();
      grpc::ClientContext ac;
      s = stub->Act(&ac, act, &acted);
      if (!s.ok()) return absl::UnavailableError(absl::StrCat("Act: ", s.error_message()));
      bool done = false;
      while (!done && reader->Read(&e)) {
        if (e.has_robot_commanded() && e.robot_commanded().emotion() == want) {
          if (!e.robot_commanded().error().empty()) {
            return absl::UnavailableError(absl::StrCat("robot: ", e.robot_commanded().error()));
          }
          done = true;
          if (i >= 10) {  // warm-up excluded
            e2e.push_back(Ms(SteadyClock::now() - t0));
            bridge_ms.push_back(e.robot_commanded().latency_ms());
          }
        }
      }
      if (!done) return absl::UnavailableError("WatchSession ended");
    }
    wctx.TryCancel();
    (void)reader->Finish();
    out.cube_to_register_p50_ms = Percentile(e2e, 0.5);
    out.cube_to_register_p99_ms = Percentile(e2e, 0.99);
    out.bridge_round_trip_p50_ms = Percentile(bridge_ms, 0.5);
    out.bridge_round_trip_p99_ms = Percentile(bridge_ms, 0.99);
    grpc::ClientContext cc;
    v1::CloseSessionRequest close;
    close.set_session_id("bench");
    v1::CloseSessionResponse closed;
    (void)stub->CloseSession(&cc, close, &closed);
  }

  // 2. Many sessions at once, each with a running model.
  {
    const auto t0 = SteadyClock::now();
    for (int i = 0; i < o.sessions; ++i) {
      v1::OpenSessionRequest open;
      open.set_session_id(absl::StrCat("load-", i));
      open.set_robot_id("pleo");
      v1::OpenSessionResponse opened;
      grpc::ClientContext c;
      if (!stub->OpenSession(&c, open, &opened).ok()) break;
      v1::ActRequest act;
      act.set_session_id(opened.session().session_id());
      act.set_action(i % 2 ? common::v1::ACTION_KISSES : common::v1::ACTION_SHOUTING);
      act.set_intensity(0.0);
      v1::ActResponse acted;
      grpc::ClientContext ac;
      if (!stub->Act(&ac, act, &acted).ok()) break;
    }
    out.sessions_open_s = std::chrono::duration<double>(SteadyClock::now() - t0).count();
    grpc::ClientContext lc;
    v1::ListSessionsResponse list;
    grpc::Status s = stub->ListSessions(&lc, v1::ListSessionsRequest(), &list);
    if (!s.ok()) return absl::UnavailableError(absl::StrCat("ListSessions: ", s.error_message()));
    int running = 0;
    for (const auto& x : list.sessions()) {
      // Every session's model has moved (its action pushed the valence).
      if (x.action() != common::v1::ACTION_IDLE && x.valence() != 0.0) ++running;
    }
    out.sessions = running;
  }
  host->Shutdown();
  coordinator->Stop();
  bridge_host->Shutdown();

  if (!o.coordinator.empty()) {
    if (Status s = MeasureAudio(o, &out); !s.ok()) {
      out.audio_note = absl::StrCat("StreamAnimate: ", s.message());
    }
  } else {
    out.audio_note = "no coordinator to stream to";
  }
  return out;
}

}  // namespace kinemo::coordinator
