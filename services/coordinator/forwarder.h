// The coordinator as the stack's front door: a generic gRPC service that
// receives every call for a method the server does not register itself and
// forwards it, byte for byte, to the service that owns it (a CLI's
// PushArtifact or Train through the coordinator's one address).
//
// Every RPC shape is a bidi stream on the wire, so one reactor serves all:
// messages are relayed one at a time in each direction (flow control is the
// slower side's), the caller's deadline and cancellation propagate to the
// callee (ClientContext::FromCallbackServerContext), the caller's metadata
// (request ids, ...) goes along, and the callee's metadata and status come
// back unchanged. Calls for a service with no endpoint answer UNAVAILABLE
// naming the option (services.inference.address); others (unknown services,
// the robot bridge, everything when forwarding is disabled) UNIMPLEMENTED
// naming the method. The coordinator's forwarder bounds every call by its
// method's class (CoordinatorOptions.deadlines: short, analysis at
// animate.max_audio_s, builds; streams keep the caller's deadline), the
// caller's own deadline winning when shorter.
//
// RPC plumbing, not core: it never looks into the messages.
#pragma once

#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <grpcpp/channel.h>
#include <grpcpp/generic/async_generic_service.h>

#include "kinemo/coordinator/v1/options.pb.h"
#include "services/coordinator/coordinator_service.h"
#include "services/coordinator/core/deadlines.h"

namespace kinemo::coordinator {

struct ForwardTarget {
  // Where calls go; null = not configured (UNAVAILABLE naming `option`).
  std::shared_ptr<grpc::Channel> channel;
  // The option that would configure it, e.g. "services.inference.address".
  std::string option;
};

class Forwarder final : public grpc::CallbackGenericService {
 public:
  // `targets` by full service name ("kinemo.inference.v1.InferenceService");
  // `refused` by full service name, with the reason given to callers.
  // `disabled`: every call is refused (CoordinatorOptions.disable_forwarding).
  // `deadlines`: the bound of each call by its method's class; none = the
  // caller's deadline only.
  Forwarder(std::map<std::string, ForwardTarget> targets, std::map<std::string, std::string> refused,
            bool disabled, std::optional<Deadlines> deadlines = std::nullopt);

  // The coordinator's forwarding: prosody, inference, planner and
  // cube_tracker over its channels; the robot bridge refused.
  static std::shared_ptr<Forwarder> ForCoordinator(const v1::CoordinatorOptions& options,
                                                   const ServiceChannels& channels);

  // A target that SetTarget will give later: calls for it wait (at most
  // `wait`, and never past their deadline) instead of being refused.
  void Expect(const std::string& service, std::chrono::milliseconds wait);
  void SetTarget(const std::string& service, ForwardTarget target);

  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* context) override;

 private:
  // The target of a call, or the status that refuses it.
  grpc::Status Resolve(const grpc::GenericCallbackServerContext& context, std::shared_ptr<grpc::Channel>* channel);

  const std::map<std::string, std::string> refused_;
  const bool disabled_;
  const std::optional<Deadlines> deadlines_;
  std::mutex mu_;
  std::condition_variable changed_;
  std::map<std::string, ForwardTarget> targets_;                    // guarded by mu_
  std::map<std::string, std::chrono::milliseconds> expected_;       // guarded by mu_
};

}  // namespace kinemo::coordinator
