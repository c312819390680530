#include "services/coordinator/bench/e2e_bench.h"
#include "services/coordinator/bench/pleo_sim_child.h"

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
#include "services/coordinator/coordinator_service.h"
#include "services/robot_bridge/robot_bridge_service.h"

namespace kinemo::coordinator {
namespace {

namespace v1 = ::kinemo::coordinator::v1;
using SteadyClock = std::chrono::steady_clock;

double Ms(SteadyClock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(p * (v.size() - 1) + 0.5));
  return v[i];
}

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

// StreamAnimate at real time: per chunk, the time until the first frames
// batch that reports it (last_chunk_sequence) arrives.
Status MeasureAudio(const E2eBenchOptions& o, E2eBenchResult* out) {
  auto audio = audio::DecodeAudioFile(o.speech_file);
  if (!audio.ok()) return audio.status();
  KINEMO_ASSIGN_OR_RETURN(auto credentials, MakeChannelCredentials(o.coordinator_tls));
  auto stub = v1::CoordinatorService::NewStub(grpc::CreateChannel(o.coordinator, credentials));
  grpc::ClientContext ctx;
  auto stream = stub->StreamAnimate(&ctx);
  v1::StreamAnimateRequest cfg;
  cfg.mutable_config()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_PCM_F32LE);
  cfg.mutable_config()->mutable_format()->set_sample_rate_hz(audio->sample_rate_hz);
  cfg.mutable_config()->mutable_format()->set_channels(1);
  cfg.mutable_config()->mutable_models()->set_inference_model_id(o.model_id);
  cfg.mutable_config()->mutable_models()->set_controller_id(o.controller_id);
  if (!stream->Write(cfg)) return absl::UnavailableError("StreamAnimate: could not start");
  const std::size_t n = static_cast<std::size_t>(audio->sample_rate_hz / 50);
  std::vector<SteadyClock::time_point> sent((audio->samples.size() + n - 1) / n);
  std::mutex mu;
  std::thread writer([&] {
    const auto t0 = SteadyClock::now();
    std::uint64_t seq = 0;
    for (std::size_t i = 0; i < audio->samples.size(); i += n, ++seq) {
      std::this_thread::sleep_until(t0 + std::chrono::milliseconds(20 * seq));
      v1::StreamAnimateRequest q;
      q.mutable_chunk()->set_sequence_number(seq);
      q.mutable_chunk()->set_start_time_s(static_cast<double>(i) / audio->sample_rate_hz);
      const std::size_t m = std::min(n, audio->samples.size() - i);
      q.mutable_chunk()->set_data(reinterpret_cast<const char*>(&audio->samples[i]), m * sizeof(float));
      {
        std::lock_guard<std::mutex> l(mu);
        sent[seq] = SteadyClock::now();
      }
      if (!stream->Write(q)) break;
    }
    stream->WritesDone();
  });
  std::vector<double> lat;
  v1::StreamAnimateResponse r;
  while (stream->Read(&r)) {
    if (!r.has_frames() || r.frames().frames().empty()) continue;
    const auto now = SteadyClock::now();
    std::lock_guard<std::mutex> l(mu);
    if (r.last_chunk_sequence() < sent.size()) lat.push_back(Ms(now - sent[r.last_chunk_sequence()]));
  }
  writer.join();
  grpc::Status s = stream->Finish();
  if (!s.ok()) return absl::UnavailableError(absl::StrCat("StreamAnimate: ", s.error_message()));
  if (lat.empty()) return absl::InternalError("StreamAnimate: no frames");
  out->audio_to_frame_p50_ms = Percentile(lat, 0.5);
  out->audio_to_frame_p99_ms = Percentile(lat, 0.99);
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
    if (Status s = MeasureAudio(o, &out); !s.ok()) out.audio_note = std::string(s.message());
  } else {
    out.audio_note = "needs --coordinator with --model and --controller (a stack with models)";
  }
  return out;
}

}  // namespace kinemo::coordinator
