// gRPC adapter of the coordinator (sync API): sessions on the core
// SessionManager, the relay to the robot bridge (RobotRelay), cube
// attachments (CubeTrackerService.TrackSource streams), and the speech ->
// animation pipeline over the prosody, inference and planner services.
//
// The other services are reached through channels: made from
// CoordinatorOptions.services addresses, or passed in (the all-in-one
// binary passes in-process channels). A service without a channel is
// "not configured": calls that need it answer UNAVAILABLE.
//
// With CoordinatorOptions.store_dir, sessions are durable (SqliteSessionStore):
// Create restores them, resumes their relays and re-subscribes their cubes.
#pragma once

#include <atomic>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <grpcpp/channel.h>

#include "common/metrics/metrics.h"
#include "common/status/status.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "kinemo/coordinator/v1/options.pb.h"
#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"
#include "services/coordinator/core/clock.h"
#include "services/coordinator/core/cube_attachment.h"
#include "services/coordinator/core/deadlines.h"
#include "services/coordinator/core/session_manager.h"

namespace kinemo::coordinator {

// Channels to the other services; null = from the options' address (or not
// configured when that is empty).
struct ServiceChannels {
  std::shared_ptr<grpc::Channel> prosody;
  std::shared_ptr<grpc::Channel> inference;
  std::shared_ptr<grpc::Channel> planner;
  std::shared_ptr<grpc::Channel> cube_tracker;
  std::shared_ptr<grpc::Channel> robot_bridge;
};

class RobotRelay;
class Watchdog;

// StreamAnimate runs on the callback API (stream_animate.cc): a reactor per
// stream with client reactors for the three downstream streams, no thread
// per stream; the other methods are synchronous.
class CoordinatorServiceImpl final
    : public v1::CoordinatorService::WithCallbackMethod_StreamAnimate<v1::CoordinatorService::Service> {
 public:
  // INVALID_ARGUMENT for bad options (naming the field).
  static StatusOr<std::shared_ptr<CoordinatorServiceImpl>> Create(
      const v1::CoordinatorOptions& options, ServiceChannels channels = {},
      const Clock* clock = SystemClock::Get());
  ~CoordinatorServiceImpl() override;

  grpc::Status OpenSession(grpc::ServerContext* context, const v1::OpenSessionRequest* request,
                           v1::OpenSessionResponse* response) override;
  grpc::Status CloseSession(grpc::ServerContext* context, const v1::CloseSessionRequest* request,
                            v1::CloseSessionResponse* response) override;
  grpc::Status ListSessions(grpc::ServerContext* context, const v1::ListSessionsRequest* request,
                            v1::ListSessionsResponse* response) override;
  grpc::Status GetSession(grpc::ServerContext* context, const v1::GetSessionRequest* request,
                          v1::Session* response) override;
  grpc::Status Act(grpc::ServerContext* context, const v1::ActRequest* request,
                   v1::ActResponse* response) override;
  grpc::Status WatchSession(grpc::ServerContext* context, const v1::WatchSessionRequest* request,
                            grpc::ServerWriter<v1::SessionEvent>* writer) override;
  grpc::Status AttachCube(grpc::ServerContext* context, const v1::AttachCubeRequest* request,
                          v1::AttachCubeResponse* response) override;
  grpc::Status DetachCube(grpc::ServerContext* context, const v1::DetachCubeRequest* request,
                          v1::DetachCubeResponse* response) override;
  grpc::Status Animate(grpc::ServerContext* context, const v1::AnimateRequest* request,
                       v1::AnimateResponse* response) override;
  grpc::ServerBidiReactor<v1::StreamAnimateRequest, v1::StreamAnimateResponse>* StreamAnimate(
      grpc::CallbackServerContext* context) override;
  // animate_chunked.cc.
  grpc::Status AnimateChunked(
      grpc::ServerContext* context,
      grpc::ServerReaderWriter<v1::AnimateChunkedResponse, v1::AnimateChunkedRequest>* stream) override;

  // Stops background threads (idempotent; the destructor calls it). With a
  // store_dir, sessions stay stored for the next start; without one, every
  // session is closed (reason "shutdown").
  void Stop();
  SessionManager& sessions() { return *manager_; }
  // The channels to the other services (null = not configured).
  const ServiceChannels& channels() const { return channels_; }

 private:
  CoordinatorServiceImpl(const v1::CoordinatorOptions& options, const SessionManagerOptions& so,
                         const Deadlines& deadlines, ServiceChannels channels, const Clock* clock,
                         std::unique_ptr<SessionStore> store);
  void TickLoop();
  void WakeTicker();
  // A cube attachment over cube_tracker_'s TrackSource (core/cube_attachment.h).
  std::unique_ptr<CubeAttachment> NewCubeAttachment(const std::string& session_id,
                                                    cube_tracker::v1::TrackSourceRequest request, bool confirm);
  // Stops and forgets the cube attachment of a session (if any).
  void DetachCubeOf(const std::string& session_id);
  // The deadline of a call that may take `seconds` from now.
  static std::chrono::system_clock::time_point DeadlineAfter(double seconds);

  const v1::CoordinatorOptions options_;
  const Deadlines deadlines_;
  // The idle timeout of downstream streams (deadlines.stream_idle_s).
  std::unique_ptr<Watchdog> watchdog_;
  const Clock* clock_;
  ServiceChannels channels_;
  std::unique_ptr<SessionStore> store_;  // null without store_dir
  std::unique_ptr<RobotRelay> relay_;
  std::unique_ptr<SessionManager> manager_;
  std::unique_ptr<prosody::v1::ProsodyService::Stub> prosody_;
  std::unique_ptr<inference::v1::InferenceService::Stub> inference_;
  std::unique_ptr<planner::v1::PlannerService::Stub> planner_;
  std::unique_ptr<cube_tracker::v1::CubeTrackerService::Stub> cube_tracker_;

  std::mutex tick_mu_;
  std::condition_variable tick_cv_;
  bool stopping_ = false;
  std::thread ticker_;

  std::mutex cubes_mu_;
  std::map<std::string, std::unique_ptr<CubeAttachment>> cubes_;
  std::atomic<int> streams_{0};
  std::atomic<int> chunked_{0};  // AnimateChunked calls running
  std::atomic<bool> stopped_{false};
  // Sessions and streams open, read when scraped; declared last: gone first.
  std::vector<std::unique_ptr<metrics::ScrapeRegistration>> metrics_;
};

// Animate's errors for a recording too long for it, with the remedy: a
// message over the size limit (RESOURCE_EXHAUSTED "... larger than max")
// and prosody's "longer than max_audio_s ... AnalyzeChunked" say to send
// long recordings with AnimateChunked; other errors unchanged.
grpc::Status WithChunkedRemedy(const grpc::Status& s);

// The service config of a channel to `endpoint`: its load-balancing policy
// (ServiceEndpoint.lb_policy), client-side health checking under
// round_robin, and retries of UNAVAILABLE calls to the stateless services.
// INVALID_ARGUMENT "<field>.lb_policy: ..." for an unknown policy.
StatusOr<std::string> ChannelServiceConfig(const v1::ServiceEndpoint& endpoint,
                                           const char* field);

// A channel to an endpoint (plaintext or TLS as configured) with the given
// message limit and ChannelServiceConfig; null for an empty address.
StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const v1::ServiceEndpoint& endpoint,
                                                     std::uint32_t max_message_bytes,
                                                     const char* field);

}  // namespace kinemo::coordinator
