// grpc.reflection.v1.ServerReflection beside gRPC's v1alpha one. gRPC 1.51
// ships only grpc.reflection.v1alpha (grpc++_reflection); v1 has the same
// messages, field for field, under another package. This service answers each
// request of a v1 stream by asking it of the v1alpha service of the same
// server, through its in-process channel, on a v1alpha stream of its own: what
// v1 clients see (the services listed, the descriptors served, the errors) is
// v1alpha's answer to that one request.
#pragma once

#include <grpcpp/channel.h>

#include <memory>
#include <mutex>

#include "grpc/reflection/v1/reflection.grpc.pb.h"

namespace kinemo::server {

class ReflectionV1Service final : public grpc::reflection::v1::ServerReflection::CallbackService {
 public:
  // The channel to this server's own v1alpha service (Server::InProcessChannel),
  // set once the server has started. Until then calls get UNAVAILABLE.
  void SetBackend(std::shared_ptr<grpc::Channel> channel);

  grpc::ServerBidiReactor<grpc::reflection::v1::ServerReflectionRequest,
                          grpc::reflection::v1::ServerReflectionResponse>*
  ServerReflectionInfo(grpc::CallbackServerContext* context) override;

 private:
  std::mutex mu_;
  std::shared_ptr<grpc::Channel> backend_;
};

}  // namespace kinemo::server
