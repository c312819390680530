// StreamAnimate with config.vmc: the coordinator sends the stream's frames
// (bones and, from their face, blend shapes) as VMC packets to a loopback
// receiver (a UDP socket here, the datagrams decoded with liblo) as they go
// to the client, counts them in the summary,
// and refuses a receiver that is not a loopback address unless its options
// name the host. Over the real prosody, inference and planner services
// (live_stack.h: the Bandai gesture library).
#include <arpa/inet.h>
#include <lo/lo.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <map>
#include <thread>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "common/audio/decode.h"
#include "services/coordinator/client/live_client.h"
#include "services/coordinator/coordinator_service.h"
#include "tests/service/coordinator/live_stack.h"

namespace kinemo::coordinator {
namespace {
namespace vmc_test {

namespace v1 = ::kinemo::coordinator::v1;

// A coordinator over the live stack (in-process channels) on loopback TCP.
struct VmcCoordinator {
  std::shared_ptr<CoordinatorServiceImpl> service;
  std::unique_ptr<server::ServiceHost> host;
  explicit VmcCoordinator(v1::CoordinatorOptions o = {}) {
    auto channel = LiveStack::Get().services->InProcessChannel();
    o.mutable_animate()->mutable_models()->set_inference_model_id("crf");
    o.mutable_animate()->mutable_models()->set_controller_id("ctrl");
    auto c = CoordinatorServiceImpl::Create(o, {channel, channel, channel, nullptr, nullptr});
    EXPECT_TRUE(c.ok()) << c.status();
    service = *c;
    host = Host({{service, v1::CoordinatorService::service_full_name()}});
  }
  std::shared_ptr<grpc::Channel> Channel() const {
    return grpc::CreateChannel(host->address(), grpc::InsecureChannelCredentials());
  }
  ~VmcCoordinator() {
    host->Shutdown();
    service->Stop();
  }
};

// A UDP socket on an ephemeral loopback port, read by a thread until Stop():
// the messages of every datagram, decoded by liblo.
class Receiver {
 public:
  Receiver() {
    fd_ = ::socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    socklen_t len = sizeof a;
    EXPECT_EQ(::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len), 0);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { Run(); });
  }
  ~Receiver() { Stop(); }
  int port() const { return port_; }
  void Stop() {
    if (!thread_.joinable()) return;
    stop_ = true;
    thread_.join();
    ::close(fd_);
  }
  int datagrams = 0;
  std::map<std::string, int> counts;  // address -> messages
  std::map<std::string, int> bones;   // bone name -> messages

 private:
  void Run() {
    std::string buf(65536, '\0');
    while (true) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) {
        if (stop_) return;
        continue;
      }
      const ssize_t n = ::recv(fd_, buf.data(), buf.size(), 0);
      if (n < 16 || std::memcmp(buf.data(), "#bundle", 8) != 0) continue;
      ++datagrams;
      for (size_t at = 16; at + 4 <= static_cast<size_t>(n);) {
        uint32_t size;
        std::memcpy(&size, buf.data() + at, 4);
        size = ntohl(size);
        at += 4;
        lo_message m = lo_message_deserialise(buf.data() + at, size, nullptr);
        if (m != nullptr) {
          const std::string address = buf.data() + at;
          ++counts[address];
          if (address == "/VMC/Ext/Bone/Pos") ++bones[&lo_message_get_argv(m)[0]->s];
          lo_message_free(m);
        }
        at += size;
      }
    }
  }
  int fd_ = -1, port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

class StreamAnimateVmc : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!LiveStack::Get().error.empty()) FAIL() << "live stack: " << LiveStack::Get().error;
  }
};

TEST_F(StreamAnimateVmc, FramesGoToALoopbackReceiverAsTheyGoToTheClient) {
  VmcCoordinator c;
  Receiver rx;
  auto audio = audio::DecodeAudioFile(kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav");
  ASSERT_TRUE(audio.ok());
  LiveStreamOptions o;
  o.realtime = true;
  o.config.mutable_vmc()->set_address("127.0.0.1:" + std::to_string(rx.port()));
  o.config.mutable_vmc()->set_bone_names(v1::VMC_BONE_NAMES_VRM1);
  auto r = RunLiveStream(c.Channel(), audio->samples, audio->sample_rate_hz, o);
  ASSERT_TRUE(r.ok()) << r.status();
  rx.Stop();  // (the datagrams left before the summary did)
  const auto& s = r->summary;
  EXPECT_EQ(s.vmc_frames(), r->frames.size());
  EXPECT_EQ(s.vmc_packets(), static_cast<uint64_t>(rx.datagrams));
  // The Bandai skeleton's humanoid: hips, spine, chest, neck, head and per
  // side shoulder, upper arm, forearm, hand, thigh, shin, foot, toes.
  EXPECT_EQ(s.vmc_bones(), 21u);
  EXPECT_EQ(rx.bones.size(), 21u);
  for (const auto& [name, n] : rx.bones) EXPECT_EQ(n, static_cast<int>(r->frames.size())) << name;
  EXPECT_TRUE(rx.bones.count("leftUpperArm") == 1 && rx.bones.count("hips") == 1);
  EXPECT_EQ(rx.counts["/VMC/Ext/T"], static_cast<int>(r->frames.size()));
  EXPECT_EQ(rx.counts["/VMC/Ext/OK"], static_cast<int>(r->frames.size()));
  EXPECT_EQ(rx.counts["/VMC/Ext/Root/Pos"], static_cast<int>(r->frames.size()));
  // Every frame carries its face (the live stack's face model): 13 VRM 1.0
  // blend shapes and an Apply per frame.
  EXPECT_EQ(s.vmc_blendshapes(), 13u);
  EXPECT_EQ(rx.counts["/VMC/Ext/Blend/Val"], 13 * static_cast<int>(r->frames.size()));
  EXPECT_EQ(rx.counts["/VMC/Ext/Blend/Apply"], static_cast<int>(r->frames.size()));
}

TEST_F(StreamAnimateVmc, OnlyLoopbackUnlessTheOptionsNameTheHost) {
  auto audio = audio::DecodeAudioFile(kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav");
  ASSERT_TRUE(audio.ok());
  std::vector<float> short_audio(audio->samples.begin(), audio->samples.begin() + audio->sample_rate_hz / 2);
  LiveStreamOptions o;
  o.realtime = false;
  {
    VmcCoordinator c;
    o.config.mutable_vmc()->set_address("192.0.2.7:39539");  // TEST-NET-1: not this machine
    auto r = RunLiveStream(c.Channel(), short_audio, audio->sample_rate_hz, o);
    ASSERT_EQ(r.status().code(), absl::StatusCode::kPermissionDenied) << r.status();
    EXPECT_TRUE(absl::StartsWith(r.status().message(), "config.vmc.address: ")) << r.status();
    o.config.mutable_vmc()->set_address("127.0.0.1:0");
    r = RunLiveStream(c.Channel(), short_audio, audio->sample_rate_hz, o);
    ASSERT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << r.status();
    EXPECT_TRUE(absl::StartsWith(r.status().message(), "config.vmc.address: ")) << r.status();
    o.config.mutable_vmc()->set_address("127.0.0.1:39539");
    o.config.mutable_vmc()->set_fps(1000);
    r = RunLiveStream(c.Channel(), short_audio, audio->sample_rate_hz, o);
    ASSERT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << r.status();
    EXPECT_TRUE(absl::StartsWith(r.status().message(), "config.vmc.fps: ")) << r.status();
  }
  {
    // Named in the options: no longer refused (it goes out, or the host has
    // no route from here: UNAVAILABLE, never PERMISSION_DENIED).
    v1::CoordinatorOptions co;
    co.mutable_animate()->add_vmc_allowed_hosts("192.0.2.7");
    VmcCoordinator c(co);
    o.config.mutable_vmc()->set_address("192.0.2.7:39539");
    o.config.mutable_vmc()->set_fps(0);
    auto r = RunLiveStream(c.Channel(), short_audio, audio->sample_rate_hz, o);
    EXPECT_NE(r.status().code(), absl::StatusCode::kPermissionDenied) << r.status();
    if (r.ok()) {
      EXPECT_EQ(r->summary.vmc_frames(), r->frames.size());
    }
  }
}

}  // namespace vmc_test
}  // namespace
}  // namespace kinemo::coordinator
