#include "common/server/reflection_v1.h"

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/support/client_callback.h>
#include <grpcpp/support/server_callback.h>

#include <chrono>
#include <mutex>

namespace kinemo::server {
namespace {

using Request = grpc::reflection::v1::ServerReflectionRequest;
using Response = grpc::reflection::v1::ServerReflectionResponse;

// The same wire format under the v1alpha method name.
constexpr char kV1AlphaMethod[] = "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo";

class Relay;

// One request asked of v1alpha on a stream of its own (gRPC 1.51's v1alpha
// service does not clear its response between the requests of a stream:
// a second list_services on one stream answers every service twice). The
// request is written and the stream half-closed before StartCall; nothing is
// started from outside this reactor, so it needs no hold. Deletes itself.
class Exchange final : public grpc::ClientBidiReactor<Request, Response> {
 public:
  Exchange(Relay* relay, grpc::TemplatedGenericStub<Request, Response>* stub,
           const Request& request, std::chrono::system_clock::time_point deadline)
      : relay_(relay), request_(request) {
    if (deadline != std::chrono::system_clock::time_point::max()) context_.set_deadline(deadline);
    stub->PrepareBidiStreamingCall(&context_, kV1AlphaMethod, grpc::StubOptions(), this);
    StartWriteLast(&request_, grpc::WriteOptions());
    StartRead(&response_);
  }
  // Once registered with the relay: from here on, OnDone may run (and delete
  // this) at any moment.
  void Start() { StartCall(); }
  void Cancel() { context_.TryCancel(); }
  void OnReadDone(bool ok) override { answered_ = ok; }
  void OnDone(const grpc::Status& status) override;

 private:
  Relay* relay_;
  grpc::ClientContext context_;
  Request request_;
  Response response_;
  bool answered_ = false;
};

// One v1 stream: each request read is answered by an Exchange with v1alpha,
// whose response is written back before the next request is read. The v1
// stream ends OK when the client has sent its last request, and with the
// exchange's status when one fails. Deletes itself.
class Relay final : public grpc::ServerBidiReactor<Request, Response> {
 public:
  Relay(grpc::CallbackServerContext* context, const std::shared_ptr<grpc::Channel>& backend)
      : stub_(backend), deadline_(context->deadline()) {
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client's last request (or a cancelled stream)
      Finish(grpc::Status::OK);
      return;
    }
    auto* exchange = new Exchange(this, &stub_, request_, deadline_);
    {
      std::lock_guard<std::mutex> lock(mu_);
      exchange_ = exchange;
    }
    exchange->Start();
  }
  // Called by the exchange once, as it ends (then it deletes itself).
  void OnExchangeDone(const grpc::Status& status, bool answered, const Response& response) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      exchange_ = nullptr;
    }
    if (!status.ok() || !answered) {
      Finish(status.ok() ? grpc::Status(grpc::StatusCode::INTERNAL, "server reflection: no answer")
                         : status);
      return;
    }
    response_ = response;
    StartWrite(&response_);
  }
  void OnWriteDone(bool ok) override {
    if (ok) {
      StartRead(&request_);
    } else {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "server reflection: the client went away"));
    }
  }
  void OnCancel() override {
    std::lock_guard<std::mutex> lock(mu_);
    if (exchange_ != nullptr) exchange_->Cancel();
  }
  void OnDone() override { delete this; }

 private:
  grpc::TemplatedGenericStub<Request, Response> stub_;
  const std::chrono::system_clock::time_point deadline_;
  Request request_;
  Response response_;
  std::mutex mu_;
  Exchange* exchange_ = nullptr;  // the one in flight, if any
};

void Exchange::OnDone(const grpc::Status& status) {
  relay_->OnExchangeDone(status, answered_, response_);
  delete this;
}

// A v1 stream that cannot be relayed.
class Refusal final : public grpc::ServerBidiReactor<Request, Response> {
 public:
  explicit Refusal(const grpc::Status& status) { Finish(status); }
  void OnDone() override { delete this; }
};

}  // namespace

void ReflectionV1Service::SetBackend(std::shared_ptr<grpc::Channel> channel) {
  std::lock_guard<std::mutex> lock(mu_);
  backend_ = std::move(channel);
}

grpc::ServerBidiReactor<Request, Response>* ReflectionV1Service::ServerReflectionInfo(
    grpc::CallbackServerContext* context) {
  std::shared_ptr<grpc::Channel> backend;
  {
    std::lock_guard<std::mutex> lock(mu_);
    backend = backend_;
  }
  if (backend == nullptr) {
    return new Refusal(
        grpc::Status(grpc::StatusCode::UNAVAILABLE, "server reflection: the server is starting"));
  }
  return new Relay(context, backend);
}

}  // namespace kinemo::server
