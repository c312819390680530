// The cube tracker's gRPC adapter (cube_tracker_service.h): the reactors of
// the streams and the unary RPCs over cube::TrackerBackend.
#include "services/cube_tracker/cube_tracker_service.h"

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

#include "common/grpc/request_check.h"
#include "common/grpc/status_mapping.h"
#include "common/logging/log.h"
#include "services/cube_tracker/core/video_source.h"

namespace kinemo::cube_tracker {

StatusOr<std::shared_ptr<CubeTrackerService>> CubeTrackerService::Create(const v1::CubeTrackerOptions& options) {
  std::shared_ptr<CubeTrackerService> svc(new CubeTrackerService());
  KINEMO_ASSIGN_OR_RETURN(svc->backend_, cube::TrackerBackend::Create(options));
  cube::TrackerBackend* backend = svc->backend_.get();
  auto push = std::make_shared<ArtifactPushHandler>();
  push->store = &backend->catalog().artifacts();
  push->kinds = {std::string(store::kCubes)};
  push->max_bytes = options.max_artifact_bytes() != 0 ? options.max_artifact_bytes() : kDefaultMaxArtifactBytes;
  push->check_header = &cube::TrackerBackend::CheckPushHeader;
  push->commit = [backend](store::Draft draft,
                           const common::v1::PushArtifactHeader& h) -> StatusOr<common::v1::PushArtifactResponse> {
    KINEMO_ASSIGN_OR_RETURN(cube::CubeCatalog::Stored stored, backend->CommitPushed(std::move(draft), h));
    common::v1::PushArtifactResponse response;
    *response.mutable_artifact() = ToProto(stored.meta);
    return response;
  };
  svc->push_ = std::move(push);
  return svc;
}

namespace {

// --- Track: frames from the client -------------------------------------------

class TrackReactor final : public grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse> {
 public:
  TrackReactor(cube::TrackerBackend* backend, grpc::CallbackServerContext* context)
      : backend_(backend), peer_(context->peer()) {
    if (Status slot = backend_->AcquireStream(); !slot.ok()) {
      Finish(ToGrpcStatus(slot));
      return;
    }
    acquired_ = true;
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client half-closed (or went away)
      Finish(grpc::Status::OK);
      return;
    }
    switch (request_.message_case()) {
      case v1::TrackRequest::kConfig: {
        if (session_) {
          Finish(ToGrpcStatus(InvalidField("config", "given twice")));
          return;
        }
        // Stream messages pass no request guard (docs/DEVELOPING.md).
        if (Status checked = CheckRequestValues(request_.config(), "config"); !checked.ok()) {
          Finish(ToGrpcStatus(checked));
          return;
        }
        auto session = backend_->NewSession(request_.config(), "config");
        if (!session.ok()) {
          log::Info("track_rejected", {{"peer", peer_}, {"error", std::string(session.status().message())}});
          Finish(ToGrpcStatus(session.status()));
          return;
        }
        session_ = std::move(*session);
        log::Info("track_started", {{"peer", peer_}, {"request_id", request_.config().request_id()}});
        StartRead(&request_);
        return;
      }
      case v1::TrackRequest::kFrame:
        if (!session_) {
          Finish(ToGrpcStatus(InvalidField("config", "must be the first message of a Track stream")));
          return;
        }
        response_.Clear();
        session_->ProcessFrame(request_.frame(), &response_);
        StartWrite(&response_);
        return;
      default:
        Finish(ToGrpcStatus(InvalidField("message", "neither config nor frame")));
    }
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(ToGrpcStatus(absl::CancelledError("write failed")));
      return;
    }
    StartRead(&request_);
  }

  void OnDone() override {
    if (acquired_) backend_->ReleaseStream();
    delete this;
  }

 private:
  cube::TrackerBackend* backend_;
  std::string peer_;
  bool acquired_ = false;
  std::unique_ptr<cube::TrackSession> session_;
  v1::TrackRequest request_;
  v1::TrackResponse response_;
};

// --- TrackSource: frames the server captures ---------------------------------

class SourceReactor final : public grpc::ServerWriteReactor<v1::TrackResponse> {
 public:
  SourceReactor(cube::TrackerBackend* backend, grpc::CallbackServerContext* context,
                const v1::TrackSourceRequest& request)
      : backend_(backend), request_(request), peer_(context->peer()) {
    if (Status slot = backend_->AcquireStream(); !slot.ok()) {
      Finish(ToGrpcStatus(slot));
      return;
    }
    acquired_ = true;
    const Status s = Open();
    if (!s.ok()) {
      log::Info("track_source_rejected", {{"peer", peer_}, {"error", std::string(s.message())}});
      Finish(ToGrpcStatus(s));
      return;
    }
    // The worker's last act is Finish(); OnDone (after it) deletes the reactor.
    std::thread([this] { Run(); }).detach();
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mu_);
    writing_ = false;
    write_failed_ = write_failed_ || !ok;
    cv_.notify_all();
  }

  void OnCancel() override {
    std::lock_guard<std::mutex> lock(mu_);
    cancelled_ = true;
    cv_.notify_all();
  }

  void OnDone() override {
    if (acquired_) backend_->ReleaseStream();
    delete this;
  }

 private:
  Status Open() {
    KINEMO_ASSIGN_OR_RETURN(session_, backend_->NewSession(request_.config(), "config"));
    KINEMO_ASSIGN_OR_RETURN(source_, cube::VideoSource::Open(request_.source(), backend_->options(),
                                                             session_->tracker().camera()));
    return absl::OkStatus();
  }

  // Waits until the write in flight is done, or until `until` (when given).
  // False if the call is over (cancelled or the write failed).
  bool Wait(std::optional<std::chrono::steady_clock::time_point> until) {
    std::unique_lock<std::mutex> lock(mu_);
    auto done = [this] { return cancelled_ || write_failed_ || !writing_; };
    if (until) {
      cv_.wait_until(lock, *until, [this] { return cancelled_ || write_failed_; });
    } else {
      cv_.wait(lock, done);
    }
    return !cancelled_ && !write_failed_;
  }

  void Run() {
    Status final_status;
    std::uint64_t sent = 0;
    cv::Mat image;
    cube::VideoSource::Frame frame;
    while (true) {
      StatusOr<bool> next = source_->Next(&image, &frame);
      if (!next.ok()) final_status = next.status();
      if (!next.ok() || !*next) break;
      if (frame.due && !Wait(frame.due)) break;
      response_.Clear();
      session_->ProcessImage(image, frame.index, frame.time_s, &response_);
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (cancelled_ || write_failed_) break;
        writing_ = true;
      }
      StartWrite(&response_);
      if (!Wait(std::nullopt)) break;
      ++sent;
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (cancelled_) final_status = absl::CancelledError("cancelled");
    }
    log::Info("track_source_done", {{"peer", peer_}, {"frames", static_cast<long long>(sent)}});
    source_.reset();  // the device or file is closed before the call ends
    Finish(ToGrpcStatus(final_status));  // nothing of `this` is touched after this call
  }

  cube::TrackerBackend* backend_;
  const v1::TrackSourceRequest request_;
  std::string peer_;
  bool acquired_ = false;
  std::unique_ptr<cube::TrackSession> session_;
  std::unique_ptr<cube::VideoSource> source_;
  v1::TrackResponse response_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool writing_ = false;
  bool write_failed_ = false;
  bool cancelled_ = false;
};

}  // namespace

grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse>* CubeTrackerService::Track(
    grpc::CallbackServerContext* context) {
  return new TrackReactor(backend_.get(), context);
}

grpc::ServerWriteReactor<v1::TrackResponse>* CubeTrackerService::TrackSource(grpc::CallbackServerContext* context,
                                                                            const v1::TrackSourceRequest* request) {
  return new SourceReactor(backend_.get(), context, *request);
}

grpc::ServerUnaryReactor* CubeTrackerService::ConfigureCube(grpc::CallbackServerContext* context,
                                                            const v1::ConfigureCubeRequest* request,
                                                            v1::ConfigureCubeResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  auto configured = backend_->Configure(*request);
  if (configured.ok()) *response = *std::move(configured);
  reactor->Finish(ToGrpcStatus(configured.status()));
  return reactor;
}

grpc::ServerReadReactor<common::v1::PushArtifactRequest>* CubeTrackerService::PushArtifact(
    grpc::CallbackServerContext* context, common::v1::PushArtifactResponse* response) {
  return NewArtifactPushReactor(context, response, push_);
}

grpc::ServerUnaryReactor* CubeTrackerService::ListArtifacts(grpc::CallbackServerContext* context,
                                                            const common::v1::ListArtifactsRequest* request,
                                                            common::v1::ListArtifactsResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  Status s = ValidateListRequest(*request, push_->kinds);
  if (s.ok()) {
    auto list = backend_->catalog().List(request->id(), request->all_versions());
    if (list.ok()) {
      AddInfos(*list, response->mutable_artifacts());
      if (backend_->catalog().in_memory()) {
        // Held in memory only: their files are not anywhere a client can use.
        response->set_in_memory(true);
        for (auto& a : *response->mutable_artifacts()) a.clear_files();
      }
    }
    s = list.status();
  }
  reactor->Finish(ToGrpcStatus(s));
  return reactor;
}

grpc::ServerUnaryReactor* CubeTrackerService::DeleteArtifact(grpc::CallbackServerContext* context,
                                                             const common::v1::DeleteArtifactRequest* request,
                                                             common::v1::DeleteArtifactResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  Status s = ValidateDeleteRequest(*request, push_->kinds);
  if (s.ok()) {
    auto removed = backend_->Delete(request->ref().id(), request->ref().version());
    if (removed.ok()) AddInfos(*removed, response->mutable_deleted());
    s = InRef(removed.status());
  }
  reactor->Finish(ToGrpcStatus(s));
  return reactor;
}

}  // namespace kinemo::cube_tracker