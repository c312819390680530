#include "services/coordinator/forwarder.h"

#include <atomic>
#include <string_view>

#include <grpcpp/client_context.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/client_callback.h>

#include "kinemo/cube_tracker/v1/cube_tracker.grpc.pb.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"

namespace kinemo::coordinator {
namespace {

// Metadata that belongs to one hop (HTTP/2 and gRPC transport headers).
bool HopByHop(std::string_view key) {
  return key.empty() || key[0] == ':' || key.rfind("grpc-", 0) == 0 || key == "content-type" ||
         key == "user-agent" || key == "te" || key == "host" || key == "accept-encoding" ||
         key == "content-encoding";
}

// "/pkg.Service/Method" -> "pkg.Service" ("" when malformed).
std::string ServiceOf(const std::string& method) {
  if (method.size() < 4 || method[0] != '/') return "";
  const std::size_t slash = method.find('/', 1);
  if (slash == std::string::npos || slash == 1 || slash + 1 >= method.size()) return "";
  return method.substr(1, slash - 1);
}

// A call that is answered at once (refused).
class Refusal final : public grpc::ServerGenericBidiReactor {
 public:
  explicit Refusal(const grpc::Status& status) { Finish(status); }
  void OnDone() override { delete this; }
};

// One forwarded call: the caller's stream (this reactor) joined to a stream
// to the callee (Upstream). Two chains run at once, each one message at a
// time: caller -> callee (read here, write there) and callee -> caller. The
// client call holds two holds, one per chain, so that it cannot complete
// while either chain may still start an operation on it; the caller's call
// is finished once the callee's has completed. Deleted when both are done.
class ForwardCall final : public grpc::ServerGenericBidiReactor {
 public:
  // `deadline_s` > 0 bounds the call (the caller's deadline, when shorter, wins).
  ForwardCall(grpc::GenericCallbackServerContext* context, const std::shared_ptr<grpc::Channel>& channel,
              double deadline_s)
      : context_(context), upstream_(this) {
    client_context_ = grpc::ClientContext::FromCallbackServerContext(*context);
    if (deadline_s > 0) {
      client_context_->set_deadline(
          std::min(context->deadline(), std::chrono::system_clock::now() +
                                            std::chrono::microseconds(static_cast<std::int64_t>(deadline_s * 1e6))));
    }
    for (const auto& [key, value] : context->client_metadata()) {
      const std::string k(key.data(), key.size());
      if (!HopByHop(k)) client_context_->AddMetadata(k, std::string(value.data(), value.size()));
    }
    grpc::GenericStub stub(channel);
    stub.PrepareBidiStreamingCall(client_context_.get(), context->method(), grpc::StubOptions(), &upstream_);
    upstream_.AddMultipleHolds(2);
    upstream_.StartRead(&down_);
    upstream_.StartCall();
    StartRead(&up_);
  }

  // --- the caller's side -------------------------------------------------
  void OnReadDone(bool ok) override {
    std::lock_guard<std::recursive_mutex> lock(mu_);
    if (!up_held_) return;  // the callee is done: drop what the caller sends
    if (!ok) {              // the caller half-closed (or went away)
      upstream_.StartWritesDone();
      ReleaseUpLocked();
      return;
    }
    upstream_.StartWrite(&up_);
  }
  void OnWriteDone(bool ok) override {
    std::lock_guard<std::recursive_mutex> lock(mu_);
    if (!ok) {  // the caller is gone
      client_context_->TryCancel();
      ReleaseDownLocked();
      return;
    }
    upstream_.StartRead(&down_);
  }
  void OnCancel() override { client_context_->TryCancel(); }
  void OnDone() override { Unref(); }

 private:
  class Upstream final : public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
   public:
    explicit Upstream(ForwardCall* call) : call_(call) {}
    void OnReadInitialMetadataDone(bool ok) override { call_->InitialMetadataReceived(ok); }
    void OnReadDone(bool ok) override { call_->DownRead(ok); }
    void OnWriteDone(bool ok) override { call_->UpWritten(ok); }
    void OnDone(const grpc::Status& status) override { call_->UpstreamDone(status); }

   private:
    ForwardCall* call_;
  };

  void InitialMetadataReceived(bool ok) {
    std::lock_guard<std::recursive_mutex> lock(mu_);
    if (ok) CopyMetadata(client_context_->GetServerInitialMetadata(), /*trailing=*/false);
    metadata_ready_ = true;
    if (write_waiting_) {
      write_waiting_ = false;
      StartWrite(&down_);
    }
  }
  void DownRead(bool ok) {
    std::lock_guard<std::recursive_mutex> lock(mu_);
    if (!ok) {  // the callee's stream ended: the call is over both ways
      ReleaseDownLocked();
      ReleaseUpLocked();
      return;
    }
    if (!metadata_ready_) {
      write_waiting_ = true;  // its initial metadata goes first
      return;
    }
    StartWrite(&down_);
  }
  void UpWritten(bool ok) {
    std::lock_guard<std::recursive_mutex> lock(mu_);
    if (!ok) {  // the callee's side is closed; its status comes with OnDone
      ReleaseUpLocked();
      return;
    }
    StartRead(&up_);
  }
  void UpstreamDone(const grpc::Status& status) {
    {
      std::lock_guard<std::recursive_mutex> lock(mu_);
      CopyMetadata(client_context_->GetServerTrailingMetadata(), /*trailing=*/true);
      Finish(status);
    }
    Unref();
  }

  void CopyMetadata(const std::multimap<grpc::string_ref, grpc::string_ref>& from, bool trailing) {
    for (const auto& [key, value] : from) {
      const std::string k(key.data(), key.size());
      if (HopByHop(k)) continue;
      if (trailing) {
        context_->AddTrailingMetadata(k, std::string(value.data(), value.size()));
      } else {
        context_->AddInitialMetadata(k, std::string(value.data(), value.size()));
      }
    }
  }
  void ReleaseUpLocked() {
    if (!up_held_) return;
    up_held_ = false;
    upstream_.RemoveHold();
  }
  void ReleaseDownLocked() {
    if (!down_held_) return;
    down_held_ = false;
    upstream_.RemoveHold();
  }
  void Unref() {
    if (refs_.fetch_sub(1) == 1) delete this;
  }

  grpc::GenericCallbackServerContext* context_;
  std::unique_ptr<grpc::ClientContext> client_context_;
  Upstream upstream_;
  grpc::ByteBuffer up_, down_;  // the message in flight in each direction
  // Start* may run a reaction inline on this thread: the lock is re-entrant.
  std::recursive_mutex mu_;
  bool up_held_ = true, down_held_ = true;
  bool metadata_ready_ = false, write_waiting_ = false;
  std::atomic<int> refs_{2};  // this reactor's OnDone and the upstream's
};

}  // namespace

Forwarder::Forwarder(std::map<std::string, ForwardTarget> targets, std::map<std::string, std::string> refused,
                     bool disabled, std::optional<Deadlines> deadlines)
    : refused_(std::move(refused)), disabled_(disabled), deadlines_(deadlines), targets_(std::move(targets)) {}

std::shared_ptr<Forwarder> Forwarder::ForCoordinator(const v1::CoordinatorOptions& options,
                                                     const ServiceChannels& channels) {
  std::map<std::string, ForwardTarget> targets = {
      {prosody::v1::ProsodyService::service_full_name(), {channels.prosody, "services.prosody.address"}},
      {inference::v1::InferenceService::service_full_name(), {channels.inference, "services.inference.address"}},
      {planner::v1::PlannerService::service_full_name(), {channels.planner, "services.planner.address"}},
      {cube_tracker::v1::CubeTrackerService::service_full_name(),
       {channels.cube_tracker, "services.cube_tracker.address"}},
  };
  std::map<std::string, std::string> refused = {
      {robot_bridge::v1::RobotBridgeService::service_full_name(),
       "the robot bridge is not forwarded (robots are driven through coordinator sessions)"}};
  // (Create has checked the options: Resolve fails only on options it refused.)
  auto deadlines = Deadlines::Resolve(options);
  return std::make_shared<Forwarder>(std::move(targets), std::move(refused), options.disable_forwarding(),
                                     deadlines.ok() ? *deadlines : Deadlines());
}

void Forwarder::Expect(const std::string& service, std::chrono::milliseconds wait) {
  std::lock_guard<std::mutex> lock(mu_);
  expected_[service] = wait;
}

void Forwarder::SetTarget(const std::string& service, ForwardTarget target) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    targets_[service] = std::move(target);
    expected_.erase(service);
  }
  changed_.notify_all();
}

grpc::Status Forwarder::Resolve(const grpc::GenericCallbackServerContext& context,
                                std::shared_ptr<grpc::Channel>* channel) {
  const std::string& method = context.method();
  const std::string service = ServiceOf(method);
  if (disabled_) {
    return grpc::Status(grpc::StatusCode::UNIMPLEMENTED,
                        kinemo::StrCat("method '", method, "': not served here, and forwarding is turned off "
                                       "(disable_forwarding)"));
  }
  if (auto it = refused_.find(service); it != refused_.end()) {
    return grpc::Status(grpc::StatusCode::UNIMPLEMENTED, kinemo::StrCat("method '", method, "': ", it->second));
  }
  std::unique_lock<std::mutex> lock(mu_);
  if (auto e = expected_.find(service); e != expected_.end()) {
    const auto until = std::min(context.deadline(), std::chrono::system_clock::now() + e->second);
    changed_.wait_until(lock, until, [&] { return expected_.count(service) == 0; });
  }
  auto it = targets_.find(service);
  if (it == targets_.end()) {
    if (expected_.count(service) != 0) {
      return grpc::Status(grpc::StatusCode::UNAVAILABLE, kinemo::StrCat("method '", method, "': still starting"));
    }
    return grpc::Status(grpc::StatusCode::UNIMPLEMENTED,
                        kinemo::StrCat("method '", method, "': no service '", service, "' at this address"));
  }
  if (it->second.channel == nullptr) {
    return grpc::Status(grpc::StatusCode::UNAVAILABLE,
                        kinemo::StrCat(it->second.option, ": not set, so '", method, "' cannot be forwarded"));
  }
  *channel = it->second.channel;
  return grpc::Status::OK;
}

grpc::ServerGenericBidiReactor* Forwarder::CreateReactor(grpc::GenericCallbackServerContext* context) {
  std::shared_ptr<grpc::Channel> channel;
  const grpc::Status refused = Resolve(*context, &channel);
  if (!refused.ok()) return new Refusal(refused);
  const double deadline_s = deadlines_ ? deadlines_->ForClass(ClassOfMethod(context->method())) : 0;
  return new ForwardCall(context, channel, deadline_s);
}

}  // namespace kinemo::coordinator
