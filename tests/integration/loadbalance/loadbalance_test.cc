// Load spread over replicas (issue 17): the coordinator reaches three prosody
// and three planner processes through one "ipv4:a,b,c" target each, with the
// round_robin policy; each replica's own GET /metrics says how many calls it
// served. Real speech (tests/data), the bundled model and controller (the
// seed store the build makes), real processes on ephemeral ports.
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/audio/decode.h"
#include "common/testing/http.h"
#include "common/testing/process.h"
#include "gtest/gtest.h"
#include "kinemo/coordinator/v1/coordinator.grpc.pb.h"
#include "services/coordinator/client/live_client.h"
#include "services/coordinator/coordinator_service.h"

namespace kinemo::coordinator {
namespace {

using kinemo::testing::HttpGet;
using kinemo::testing::MetricSum;
using kinemo::testing::ServiceProcess;
using namespace std::chrono_literals;

const std::string kBin = KINEMO_BINARY_DIR;
const std::string kData = KINEMO_TEST_DATA_DIR;
const std::string kSpeech = kData + "/speech/sense_and_sensibility_01_austen_64kb-0870.wav";

// Calls of `service` that replica `p` started, summed over `methods`.
double Served(ServiceProcess& p, const std::string& service, const std::vector<std::string>& methods) {
  auto text = HttpGet("127.0.0.1", p.metrics_port(), "/metrics");
  EXPECT_TRUE(text.ok()) << text.status();
  if (!text.ok()) return -1;
  double n = 0;
  for (const std::string& m : methods) {
    n += MetricSum(*text, "kinemo_rpc_started_total", {{"method", "/" + service + "/" + m}});
  }
  return n;
}

std::string Targets(const std::vector<std::unique_ptr<ServiceProcess>>& replicas) {
  std::string out = "ipv4:";
  for (std::size_t i = 0; i < replicas.size(); ++i) out += (i ? "," : "") + replicas[i]->address();
  return out;
}

class LoadBalance : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string seed = kBin + "/share/kinemo/store";
    ASSERT_TRUE(std::ifstream(seed + "/controllers/bundled/1/artifact.json").good()) << seed;
    for (int i = 0; i < 3; ++i) {
      auto p = ServiceProcess::Start({.binary = kBin + "/services/prosody/prosody", .metrics = true});
      ASSERT_TRUE(p.ok()) << p.status();
      prosody_.push_back(std::move(*p));
      const std::string cfg = dir_.File("planner" + std::to_string(i) + ".textproto");
      std::ofstream(cfg) << "store_dir: \"" << dir_.File("planner-store" + std::to_string(i)) << "\"\n"
                         << "seed_store_dir: \"" << seed << "\"\n"
                         << "library_root: \"" << kData << "\"\n"
                         << "preload { library_id: \"bundled\" paths: \"planner_gesture\" paths: \"planner_controller\" }\n";
      auto q = ServiceProcess::Start(
          {.binary = kBin + "/services/planner/planner", .args = {"--config", cfg}, .metrics = true});
      ASSERT_TRUE(q.ok()) << q.status();
      planner_.push_back(std::move(*q));
    }
    std::ofstream(dir_.File("inference.textproto"))
        << "store_dir: \"" << dir_.File("inference-store") << "\"\nseed_store_dir: \"" << seed << "\"\n";
    auto inference = ServiceProcess::Start(
        {.binary = kBin + "/services/inference/inference", .args = {"--config", dir_.File("inference.textproto")}});
    ASSERT_TRUE(inference.ok()) << inference.status();
    inference_ = std::move(*inference);
    // No lb_policy: round_robin is the default for TCP targets.
    std::ofstream(dir_.File("coordinator.textproto"))
        << "services {\n"
        << "  prosody { address: \"" << Targets(prosody_) << "\" deadline_s: 30 }\n"
        << "  inference { address: \"" << inference_->address() << "\" deadline_s: 30 }\n"
        << "  planner { address: \"" << Targets(planner_) << "\" deadline_s: 30 }\n"
        << "}\n"
        << "animate { models { inference_model_id: \"bundled\" controller_id: \"bundled\" } }\n";
    auto coordinator = ServiceProcess::Start({.binary = kBin + "/services/coordinator/coordinator",
                                              .args = {"--config", dir_.File("coordinator.textproto")},
                                              .metrics = true});
    ASSERT_TRUE(coordinator.ok()) << coordinator.status();
    coordinator_ = std::move(*coordinator);
    auto audio = audio::DecodeAudioFile(kSpeech);
    ASSERT_TRUE(audio.ok()) << audio.status();
    audio_ = std::move(*audio);
  }

  Status Stream() {
    LiveStreamOptions o;
    o.realtime = false;
    o.config.set_request_id("loadbalance");
    return RunLiveStream(coordinator_->Channel(), audio_.samples, audio_.sample_rate_hz, o).status();
  }

  grpc::Status Animate() {
    auto stub = v1::CoordinatorService::NewStub(coordinator_->Channel());
    v1::AnimateRequest request;
    std::ifstream in(kSpeech, std::ios::binary);
    request.mutable_audio()->set_data(std::string(std::istreambuf_iterator<char>(in), {}));
    request.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
    request.set_request_id("loadbalance");
    v1::AnimateResponse response;
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 60s);
    return stub->Animate(&ctx, request, &response);
  }

  kinemo::testing::TempDir dir_;
  std::vector<std::unique_ptr<ServiceProcess>> prosody_, planner_;
  std::unique_ptr<ServiceProcess> inference_, coordinator_;
  audio::DecodedAudio audio_;
};

TEST(ChannelPolicy, RoundRobinForTcpTargetsPickFirstForUnixSocketsAndUnknownPoliciesRefused) {
  v1::ServiceEndpoint e;
  e.set_address("ipv4:127.0.0.1:1,127.0.0.1:2");
  auto config = ChannelServiceConfig(e, "services.planner");
  ASSERT_TRUE(config.ok()) << config.status();
  EXPECT_NE(config->find(R"({"round_robin":{}})"), std::string::npos) << *config;
  EXPECT_NE(config->find("healthCheckConfig"), std::string::npos) << *config;
  EXPECT_NE(config->find("kinemo.planner.v1.PlannerService"), std::string::npos) << *config;
  e.set_address("unix:/tmp/planner.sock");
  config = ChannelServiceConfig(e, "services.planner");
  ASSERT_TRUE(config.ok());
  EXPECT_NE(config->find(R"({"pick_first":{}})"), std::string::npos) << *config;
  e.set_lb_policy("random");
  config = ChannelServiceConfig(e, "services.planner");
  ASSERT_FALSE(config.ok());
  EXPECT_EQ(config.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(config.status().message().rfind("services.planner.lb_policy: ", 0), 0u) << config.status();
  // The coordinator refuses such options at start (exit code 2), naming the field.
  kinemo::testing::TempDir dir;
  std::ofstream(dir.File("co.textproto")) << "services { planner { address: \"127.0.0.1:1\" lb_policy: \"random\" } }\n";
  auto coordinator = ServiceProcess::Start(
      {.binary = kBin + "/services/coordinator/coordinator", .args = {"--config", dir.File("co.textproto")}});
  ASSERT_FALSE(coordinator.ok());
  EXPECT_NE(std::string(coordinator.status().message()).find("services.planner.lb_policy"), std::string::npos)
      << coordinator.status();
}

TEST_F(LoadBalance, CallsAndStreamsReachEveryReplicaAndLosingOneFailsNoNewStream) {
  // Unary Animate (prosody.Analyze, planner.Synthesize) and StreamAnimate
  // (prosody.StreamAnalyze, planner.Control), several of each.
  for (int i = 0; i < 6; ++i) {
    const grpc::Status a = Animate();
    ASSERT_TRUE(a.ok()) << a.error_code() << " " << a.error_message();
    const Status s = Stream();
    ASSERT_TRUE(s.ok()) << s;
  }
  const std::string pr = "kinemo.prosody.v1.ProsodyService", pl = "kinemo.planner.v1.PlannerService";
  for (int i = 0; i < 3; ++i) {
    const double unary_prosody = Served(*prosody_[i], pr, {"Analyze"});
    const double stream_prosody = Served(*prosody_[i], pr, {"StreamAnalyze"});
    const double unary_planner = Served(*planner_[i], pl, {"Synthesize"});
    const double stream_planner = Served(*planner_[i], pl, {"Control"});
    std::printf("replica %d: prosody Analyze %.0f StreamAnalyze %.0f, planner Synthesize %.0f Control %.0f\n", i,
                unary_prosody, stream_prosody, unary_planner, stream_planner);
    EXPECT_GT(unary_prosody, 0) << "prosody replica " << i;
    EXPECT_GT(stream_prosody, 0) << "prosody replica " << i;
    EXPECT_GT(unary_planner, 0) << "planner replica " << i;
    EXPECT_GT(stream_planner, 0) << "planner replica " << i;
  }
  // The coordinator counted its own calls too.
  auto coordinator_metrics = HttpGet("127.0.0.1", coordinator_->metrics_port(), "/metrics");
  ASSERT_TRUE(coordinator_metrics.ok());
  EXPECT_EQ(MetricSum(*coordinator_metrics, "kinemo_rpc_handled_total",
                      {{"method", "/kinemo.coordinator.v1.CoordinatorService/StreamAnimate"}, {"code", "OK"}}),
            6);

  // Streams keep running on four client threads while one prosody and one
  // planner replica are killed (SIGKILL: no goodbye). Streams in flight on
  // them may fail; every stream started after the kill must succeed.
  std::atomic<bool> killed{false}, stop{false};
  std::atomic<int> before_kill{0}, after_kill{0}, failed_in_flight{0};
  std::mutex mu;
  std::vector<std::string> new_failures;
  std::vector<std::thread> clients;
  for (int t = 0; t < 4; ++t) {
    clients.emplace_back([&] {
      while (!stop.load()) {
        const bool started_after = killed.load();
        const Status s = Stream();
        if (started_after) {
          ++after_kill;
          if (!s.ok()) {
            std::lock_guard<std::mutex> l(mu);
            new_failures.push_back(std::string(s.message()));
          }
        } else {
          ++before_kill;
          if (!s.ok()) ++failed_in_flight;
        }
      }
    });
  }
  const auto until = std::chrono::steady_clock::now() + 120s;
  while (before_kill.load() < 4 && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(10ms);
  const pid_t prosody_pid = prosody_[0]->process().pid(), planner_pid = planner_[0]->process().pid();
  ASSERT_EQ(::kill(prosody_pid, SIGKILL), 0);
  ASSERT_EQ(::kill(planner_pid, SIGKILL), 0);
  killed = true;
  while (after_kill.load() < 12 && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(10ms);
  stop = true;
  for (auto& c : clients) c.join();
  std::printf("streams: %d before the kill (%d failed in flight), %d started after it\n", before_kill.load(),
              failed_in_flight.load(), after_kill.load());
  EXPECT_GE(after_kill.load(), 12);
  EXPECT_TRUE(new_failures.empty()) << new_failures.size() << " new streams failed, first: " << new_failures.front();
  // The survivors served the streams started after the kill.
  for (int i = 1; i < 3; ++i) {
    EXPECT_GT(Served(*planner_[i], pl, {"Control"}), 2) << "planner replica " << i;
  }
}

}  // namespace
}  // namespace kinemo::coordinator
