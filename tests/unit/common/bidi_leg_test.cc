// ClientBidiLeg (common/grpc/bidi_leg.h) over a real gRPC server in this
// process: an echo of StreamInfer (one belief per features message) that can
// end early or stall, and an owner that drives the leg under its mutex as
// the coordinator's StreamAnimate does.
#include "common/grpc/bidi_leg.h"

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <future>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "gtest/gtest.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"

namespace kinemo {
namespace {

namespace inf = ::kinemo::inference::v1;
using namespace std::chrono_literals;
using Leg = ClientBidiLeg<inf::StreamInferRequest, inf::StreamInferResponse>;

// Echoes every features message as a belief of the same span; with
// `end_after` > 0 it ends the call (OK) after that many; messages with
// start_s < 0 are not answered.
class EchoInference final : public inf::InferenceService::Service {
 public:
  explicit EchoInference(int end_after = 0) : end_after_(end_after) {}
  grpc::Status StreamInfer(grpc::ServerContext*,
                           grpc::ServerReaderWriter<inf::StreamInferResponse, inf::StreamInferRequest>* stream)
      override {
    inf::StreamInferRequest q;
    int n = 0;
    while (stream->Read(&q)) {
      if (q.features().start_s() < 0) continue;
      inf::StreamInferResponse r;
      r.mutable_filtered()->set_start_s(q.features().start_s());
      r.mutable_filtered()->set_end_s(q.features().end_s());
      if (!stream->Write(r)) break;
      if (end_after_ > 0 && ++n == end_after_) return grpc::Status::OK;
    }
    return grpc::Status::OK;
  }

 private:
  const int end_after_;
};

struct Server {
  explicit Server(int end_after = 0) : service(end_after) {
    grpc::ServerBuilder b;
    b.RegisterService(&service);
    server = b.BuildAndStart();
    stub = inf::InferenceService::NewStub(server->InProcessChannel(grpc::ChannelArguments()));
  }
  ~Server() { server->Shutdown(std::chrono::system_clock::now() + 1s); }
  EchoInference service;
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<inf::InferenceService::Stub> stub;
};

// Drives one leg and records what it heard.
struct Owner {
  std::mutex mu;
  std::condition_variable cv;
  Leg* leg = nullptr;  // null once done
  std::vector<double> starts;
  bool done = false, closed = false;
  grpc::Status status;
  int pumps = 0;

  static Leg* Open(const std::shared_ptr<Owner>& self, inf::InferenceService::Stub* stub,
                   std::shared_ptr<void> keep = nullptr) {
    Leg::Owner o;
    o.keep = keep != nullptr ? std::move(keep) : self;
    o.mu = &self->mu;
    Owner* me = self.get();
    o.on_message = [me](inf::StreamInferResponse& r) { me->starts.push_back(r.filtered().start_s()); };
    o.on_done = [me](const grpc::Status& s, bool closed) {
      me->leg = nullptr;
      me->done = true;
      me->closed = closed;
      me->status = s;
    };
    o.pump = [me] {
      ++me->pumps;
      if (me->leg != nullptr) me->leg->Pump();
      me->cv.notify_all();
    };
    auto context = std::make_unique<grpc::ClientContext>();
    context->set_deadline(std::chrono::system_clock::now() + 20s);
    auto* leg = new Leg(std::move(o), std::move(context));
    stub->async()->StreamInfer(leg->context(), leg);
    self->leg = leg;
    return leg;
  }
  template <typename Pred>
  bool WaitFor(Pred pred) {
    std::unique_lock<std::mutex> l(mu);
    return cv.wait_for(l, 10s, [&] { return pred(); });
  }
};

inf::StreamInferRequest Step(double start_s) {
  inf::StreamInferRequest q;
  q.mutable_features()->set_start_s(start_s);
  q.mutable_features()->set_end_s(start_s + 0.1);
  return q;
}

TEST(GrpcBidiLeg, WritesInOrderReadsEveryAnswerAndEndsAfterClose) {
  Server server;
  auto owner = std::make_shared<Owner>();
  {
    std::lock_guard<std::mutex> l(owner->mu);
    Leg* leg = Owner::Open(owner, server.stub.get());
    EXPECT_EQ(leg->stalled_since(), Leg::Clock::time_point::max());
    for (int i = 0; i < 40; ++i) leg->Send(Step(0.1 * i), /*owes=*/i == 0);
    EXPECT_NE(leg->stalled_since(), Leg::Clock::time_point::max());  // an answer is owed
    EXPECT_EQ(leg->queued(), 40u);
    leg->Begin();
    leg->Pump();
  }
  ASSERT_TRUE(owner->WaitFor([&] { return owner->starts.size() == 40 && owner->leg->queued() == 0; }));
  {
    std::lock_guard<std::mutex> l(owner->mu);
    ASSERT_NE(owner->leg, nullptr);
    EXPECT_EQ(owner->leg->queued(), 0u);
    EXPECT_EQ(owner->leg->stalled_since(), Leg::Clock::time_point::max());  // answered: nothing owed
    owner->leg->Send(Step(4.0));
    owner->leg->Close();
    owner->leg->Send(Step(5.0));  // after Close: dropped
    EXPECT_TRUE(owner->leg->closing());
    EXPECT_NE(owner->leg->stalled_since(), Leg::Clock::time_point::max());  // its end is owed
    owner->leg->Pump();
  }
  ASSERT_TRUE(owner->WaitFor([&] { return owner->done; }));
  std::lock_guard<std::mutex> l(owner->mu);
  EXPECT_TRUE(owner->status.ok()) << owner->status.error_message();
  EXPECT_TRUE(owner->closed);
  ASSERT_EQ(owner->starts.size(), 41u);
  for (std::size_t i = 0; i < 40; ++i) EXPECT_DOUBLE_EQ(owner->starts[i], 0.1 * static_cast<double>(i));
  EXPECT_DOUBLE_EQ(owner->starts[40], 4.0);
  EXPECT_GT(owner->pumps, 0);
}

TEST(GrpcBidiLeg, AServerThatEndsFirstIsReportedAsNotClosed) {
  Server server(/*end_after=*/3);
  auto owner = std::make_shared<Owner>();
  {
    std::lock_guard<std::mutex> l(owner->mu);
    Leg* leg = Owner::Open(owner, server.stub.get());
    for (int i = 0; i < 10; ++i) leg->Send(Step(i));
    leg->Begin();
    leg->Pump();
  }
  ASSERT_TRUE(owner->WaitFor([&] { return owner->done; }));
  std::lock_guard<std::mutex> l(owner->mu);
  EXPECT_TRUE(owner->status.ok());
  EXPECT_FALSE(owner->closed);
  EXPECT_EQ(owner->starts.size(), 3u);
}

TEST(GrpcBidiLeg, CancelEndsTheCallAndTheOwnerIsReleasedAfterItsEnd) {
  Server server;
  auto owner = std::make_shared<Owner>();
  std::promise<void> released;
  std::future<void> let_go = released.get_future();
  {
    std::lock_guard<std::mutex> l(owner->mu);
    std::shared_ptr<void> keep(new int(0), [&released](int* p) {
      delete p;
      released.set_value();
    });
    Leg* leg = Owner::Open(owner, server.stub.get(), std::move(keep));
    leg->Send(Step(-1), /*owes=*/true);  // never answered: the leg stalls
    leg->Begin();
    leg->Pump();
  }
  ASSERT_TRUE(owner->WaitFor([&] { return owner->leg != nullptr && owner->leg->queued() == 0; }));
  {
    std::lock_guard<std::mutex> l(owner->mu);
    EXPECT_LT(owner->leg->stalled_since(), Leg::Clock::now());
    owner->leg->Cancel();
    owner->leg->Send(Step(1));
    owner->leg->Pump();  // cancelled: writes nothing
  }
  ASSERT_TRUE(owner->WaitFor([&] { return owner->done; }));
  {
    std::lock_guard<std::mutex> l(owner->mu);
    EXPECT_EQ(owner->status.error_code(), grpc::StatusCode::CANCELLED);
    EXPECT_TRUE(owner->starts.empty());
  }
  // The leg lets go of what it kept once its end was told.
  EXPECT_EQ(let_go.wait_for(10s), std::future_status::ready);
}

}  // namespace
}  // namespace kinemo
