// The coordinator's forwarder between a real gRPC client and a peer that
// echoes (a generic callback service on its own in-process server): streams
// are relayed in order both ways, the caller's metadata reaches the peer and
// the peer's metadata and status come back unchanged, the caller's deadline
// and cancellation reach the peer, and refusals name the method or option.
#include "services/coordinator/forwarder.h"

#include <condition_variable>
#include <future>
#include <mutex>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "common/server/service_host.h"
#include "kinemo/inference/v1/inference.grpc.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "kinemo/robot_bridge/v1/robot_bridge.grpc.pb.h"

namespace kinemo::coordinator {
namespace {

using namespace std::chrono_literals;

std::string Text(const grpc::ByteBuffer& b) {
  std::vector<grpc::Slice> slices;
  (void)b.Dump(&slices);
  std::string out;
  for (const auto& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}
grpc::ByteBuffer Buffer(const std::string& text) {
  grpc::Slice slice(text);
  return grpc::ByteBuffer(&slice, 1);
}

// What the peer saw of the last call.
struct PeerLog {
  std::mutex mu;
  std::condition_variable cv;
  std::string request_id;
  std::chrono::system_clock::time_point deadline;
  bool cancelled = false;
  int calls = 0;  // calls that reached the peer
};

// The peer: "/test.Echo/Echo" answers each message with "echo:" + message and
// finishes OK after the caller half-closes, with metadata of its own;
// "/test.Echo/Fail" finishes with INVALID_ARGUMENT at once; "/test.Echo/Hang"
// never answers and records its cancellation.
class EchoPeer final : public grpc::CallbackGenericService {
 public:
  explicit EchoPeer(PeerLog* log) : log_(log) {}
  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* ctx) override {
    {
      std::lock_guard<std::mutex> lock(log_->mu);
      auto it = ctx->client_metadata().find("x-request-id");
      log_->request_id = it == ctx->client_metadata().end() ? "" : std::string(it->second.data(), it->second.size());
      log_->deadline = ctx->deadline();
      log_->cancelled = false;
      ++log_->calls;
    }
    log_->cv.notify_all();
    return new Call(ctx, log_);
  }

 private:
  class Call final : public grpc::ServerGenericBidiReactor {
   public:
    Call(grpc::GenericCallbackServerContext* ctx, PeerLog* log) : ctx_(ctx), log_(log) {
      if (ctx->method() == "/test.Echo/Fail") {
        Finish(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "params.pitch_floor_hz: -1 is below 0"));
        return;
      }
      if (ctx->method() == "/test.Echo/Hang") return;  // until cancelled
      ctx_->AddInitialMetadata("x-peer", "echo");
      ctx_->AddTrailingMetadata("x-peer-count", "0");
      StartRead(&in_);
    }
    void OnReadDone(bool ok) override {
      if (!ok) {
        Finish(grpc::Status::OK);
        return;
      }
      std::string answer = "echo:";
      answer += Text(in_);
      out_ = Buffer(answer);
      StartWrite(&out_);
    }
    void OnWriteDone(bool ok) override {
      if (ok) StartRead(&in_);
    }
    void OnCancel() override {
      {
        std::lock_guard<std::mutex> lock(log_->mu);
        log_->cancelled = true;
      }
      log_->cv.notify_all();
      if (ctx_->method() == "/test.Echo/Hang") Finish(grpc::Status::CANCELLED);
    }
    void OnDone() override { delete this; }

   private:
    grpc::GenericCallbackServerContext* ctx_;
    PeerLog* log_;
    grpc::ByteBuffer in_, out_;
  };
  PeerLog* log_;
};

// A generic bidi call from the test: writes `messages`, half-closes, reads
// every answer; Wait() gives the status.
class Caller final : public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  Caller(grpc::GenericStub* stub, grpc::ClientContext* ctx, const std::string& method,
         std::vector<std::string> messages)
      : messages_(std::move(messages)) {
    stub->PrepareBidiStreamingCall(ctx, method, grpc::StubOptions(), this);
    StartRead(&in_);
    WriteNext();
    StartCall();
  }
  void OnWriteDone(bool ok) override {
    if (ok) WriteNext();
  }
  void OnReadDone(bool ok) override {
    if (!ok) return;
    answers.push_back(Text(in_));
    StartRead(&in_);
  }
  void OnDone(const grpc::Status& s) override { done_.set_value(s); }
  grpc::Status Wait() { return done_.get_future().get(); }
  std::vector<std::string> answers;

 private:
  void WriteNext() {
    if (next_ == messages_.size()) {
      StartWritesDone();
      return;
    }
    out_ = Buffer(messages_[next_++]);
    StartWrite(&out_);
  }
  std::vector<std::string> messages_;
  std::size_t next_ = 0;
  grpc::ByteBuffer in_, out_;
  std::promise<grpc::Status> done_;
};

class ForwarderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto peer = server::ServiceHost::StartInProcess("echo", {{.generic = std::make_shared<EchoPeer>(&log_)}},
                                                    16 << 20);
    ASSERT_TRUE(peer.ok()) << peer.status();
    peer_ = *std::move(peer);
    forwarder_ = std::make_shared<Forwarder>(
        std::map<std::string, ForwardTarget>{
            {"test.Echo", {peer_->InProcessChannel(), "services.echo.address"}},
            {planner::v1::PlannerService::service_full_name(), {nullptr, "services.planner.address"}}},
        std::map<std::string, std::string>{{robot_bridge::v1::RobotBridgeService::service_full_name(),
                                            "the robot bridge is not forwarded"}},
        false);
    common::v1::ServerOptions so;
    so.set_host("127.0.0.1");
    so.set_port(0);
    so.set_shutdown_grace_s(1);
    auto front = server::ServiceHost::Start(so, "front", {{.generic = forwarder_}});
    ASSERT_TRUE(front.ok()) << front.status();
    front_ = *std::move(front);
    channel_ = grpc::CreateChannel(front_->address(), grpc::InsecureChannelCredentials());
    stub_ = std::make_unique<grpc::GenericStub>(channel_);
  }
  void TearDown() override {
    if (front_) front_->Shutdown();
    if (peer_) peer_->Shutdown();
  }

  PeerLog log_;
  std::unique_ptr<server::ServiceHost> peer_, front_;
  std::shared_ptr<Forwarder> forwarder_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<grpc::GenericStub> stub_;
};

TEST_F(ForwarderTest, StreamsMetadataAndStatusPassThrough) {
  grpc::ClientContext ctx;
  ctx.AddMetadata("x-request-id", "req-42");
  const auto deadline = std::chrono::system_clock::now() + 20s;
  ctx.set_deadline(deadline);
  std::vector<std::string> sent;
  for (int i = 0; i < 50; ++i) {
    std::string m = std::to_string(i);
    m.append(static_cast<std::size_t>(i) * 1000, 'x');  // up to 49 kB
    sent.push_back(std::move(m));
  }
  Caller call(stub_.get(), &ctx, "/test.Echo/Echo", sent);
  const grpc::Status s = call.Wait();
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(call.answers.size(), sent.size());
  for (std::size_t i = 0; i < sent.size(); ++i) EXPECT_EQ(call.answers[i], std::string("echo:").append(sent[i]));
  {
    std::lock_guard<std::mutex> lock(log_.mu);
    EXPECT_EQ(log_.request_id, "req-42");
    // The caller's deadline, as the peer saw it (to the transport's rounding).
    EXPECT_LT(std::chrono::abs(log_.deadline - deadline), 1s);
  }
  auto initial = ctx.GetServerInitialMetadata().find("x-peer");
  ASSERT_NE(initial, ctx.GetServerInitialMetadata().end());
  EXPECT_EQ(std::string(initial->second.data(), initial->second.size()), "echo");
  EXPECT_NE(ctx.GetServerTrailingMetadata().find("x-peer-count"), ctx.GetServerTrailingMetadata().end());
}

TEST_F(ForwarderTest, ErrorsComeBackUnchanged) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 10s);
  Caller call(stub_.get(), &ctx, "/test.Echo/Fail", {"a", "b"});
  const grpc::Status s = call.Wait();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message(), "params.pitch_floor_hz: -1 is below 0");
}

TEST_F(ForwarderTest, DeadlineAndCancellationReachThePeer) {
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 300ms);
    Caller call(stub_.get(), &ctx, "/test.Echo/Hang", {"a"});
    EXPECT_EQ(call.Wait().error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
    std::unique_lock<std::mutex> lock(log_.mu);
    EXPECT_TRUE(log_.cv.wait_for(lock, 10s, [&] { return log_.cancelled; })) << "the peer's call outlived the deadline";
  }
  int before = 0;
  {
    std::lock_guard<std::mutex> lock(log_.mu);
    before = log_.calls;
  }
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 30s);
  Caller call(stub_.get(), &ctx, "/test.Echo/Hang", {"a"});
  {
    // Cancel once the peer has the call.
    std::unique_lock<std::mutex> lock(log_.mu);
    ASSERT_TRUE(log_.cv.wait_for(lock, 10s, [&] { return log_.calls > before; }));
  }
  ctx.TryCancel();
  EXPECT_EQ(call.Wait().error_code(), grpc::StatusCode::CANCELLED);
  std::unique_lock<std::mutex> lock(log_.mu);
  EXPECT_TRUE(log_.cv.wait_for(lock, 10s, [&] { return log_.cancelled; })) << "the cancellation did not reach the peer";
}

TEST_F(ForwarderTest, RefusalsNameTheMethodOrTheOption) {
  auto call = [&](const std::string& method) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 10s);
    Caller c(stub_.get(), &ctx, method, {});
    return c.Wait();
  };
  grpc::Status s = call("/kinemo.robot_bridge.v1.RobotBridgeService/SetEmotion");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNIMPLEMENTED);
  EXPECT_NE(s.error_message().find("/kinemo.robot_bridge.v1.RobotBridgeService/SetEmotion"), std::string::npos);
  s = call("/kinemo.nothing.v1.Nothing/Do");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNIMPLEMENTED);
  EXPECT_NE(s.error_message().find("/kinemo.nothing.v1.Nothing/Do"), std::string::npos);
  s = call("/kinemo.planner.v1.PlannerService/ListArtifacts");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(s.error_message().rfind("services.planner.address: ", 0), 0u) << s.error_message();

  // Turned off: everything is refused, naming the option.
  auto off = std::make_shared<Forwarder>(std::map<std::string, ForwardTarget>{{"test.Echo", {peer_->InProcessChannel(), ""}}},
                                         std::map<std::string, std::string>{}, true);
  auto host = server::ServiceHost::StartInProcess("off", {{.generic = off}}, 16 << 20);
  ASSERT_TRUE(host.ok());
  grpc::GenericStub stub((*host)->InProcessChannel());
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 10s);
  Caller c(&stub, &ctx, "/test.Echo/Echo", {"a"});
  s = c.Wait();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNIMPLEMENTED);
  EXPECT_NE(s.error_message().find("disable_forwarding"), std::string::npos);
  (*host)->Shutdown();
}

}  // namespace
}  // namespace kinemo::coordinator
