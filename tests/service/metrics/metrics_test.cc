// RPC metrics counted by the one interceptor every ServiceHost installs,
// values read at scrape time (OnScrape), the /metrics HTTP endpoint, and the
// metrics options' validation.
#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>

#include <grpcpp/create_channel.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/security/credentials.h>

#include "common/config/options.h"
#include "common/metrics/metrics.h"
#include "common/server/rpc_metrics.h"
#include "common/server/service_host.h"
#include "common/testing/http.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace kinemo::server {
namespace {

using grpc::health::v1::Health;
using kinemo::testing::HttpGet;
using kinemo::testing::MetricSum;

constexpr char kCheck[] = "/grpc.health.v1.Health/Check";

common::v1::ServerOptions Loopback() {
  common::v1::ServerOptions o;
  o.set_host("127.0.0.1");
  o.set_shutdown_grace_s(1);
  return o;
}

grpc::Status Check(const std::shared_ptr<grpc::Channel>& ch, const std::string& service) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::health::v1::HealthCheckRequest req;
  req.set_service(service);
  grpc::health::v1::HealthCheckResponse resp;
  return Health::NewStub(ch)->Check(&ctx, req, &resp);
}

TEST(RpcMetrics, CountsCallsByMethodAndCodeWithLatencyAndNothingInFlightAfter) {
  auto host = ServiceHost::Start(Loopback(), "metrics_test", {});
  ASSERT_TRUE(host.ok()) << host.status();
  auto channel = grpc::CreateChannel((*host)->address(), grpc::InsecureChannelCredentials());
  const std::string before = metrics::TextExposition();
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(Check(channel, "").ok());
  // An unknown service name: NOT_FOUND, counted under its own code.
  ASSERT_EQ(Check(channel, "no.such.Service").error_code(), grpc::StatusCode::NOT_FOUND);
  const std::string after = metrics::TextExposition();
  auto delta = [&](const char* name, std::vector<std::pair<std::string, std::string>> labels) {
    return MetricSum(after, name, labels) - MetricSum(before, name, labels);
  };
  EXPECT_EQ(delta("kinemo_rpc_started_total", {{"method", kCheck}}), 6);
  EXPECT_EQ(delta("kinemo_rpc_handled_total", {{"method", kCheck}, {"code", "OK"}}), 5);
  EXPECT_EQ(delta("kinemo_rpc_handled_total", {{"method", kCheck}, {"code", "NOT_FOUND"}}), 1);
  EXPECT_EQ(delta("kinemo_rpc_handling_seconds_count", {{"method", kCheck}, {"code", "OK"}}), 5);
  const double seconds = delta("kinemo_rpc_handling_seconds_sum", {{"method", kCheck}, {"code", "OK"}});
  EXPECT_GT(seconds, 0);
  EXPECT_LT(seconds, 5);
  // The +Inf bucket holds every observation.
  EXPECT_EQ(delta("kinemo_rpc_handling_seconds_bucket", {{"method", kCheck}, {"code", "OK"}, {"le", "+Inf"}}), 5);
  EXPECT_EQ(MetricSum(after, "kinemo_rpc_in_flight", {{"method", kCheck}}), 0);
}

TEST(RpcMetrics, ACallToAnUnknownMethodIsUnimplementedAndLeavesNothingInFlight) {
  auto host = ServiceHost::Start(Loopback(), "metrics_test", {});
  ASSERT_TRUE(host.ok()) << host.status();
  auto channel = grpc::CreateChannel((*host)->address(), grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::Slice empty("");
  grpc::ByteBuffer request(&empty, 1), response;
  std::mutex mu;
  std::condition_variable cv;
  bool done = false;
  grpc::Status status;
  stub.UnaryCall(&ctx, "/kinemo.nothing.v1.Nothing/Call", grpc::StubOptions(), &request, &response,
                 [&](grpc::Status s) {
                   std::lock_guard<std::mutex> l(mu);
                   status = s;
                   done = true;
                   cv.notify_all();
                 });
  std::unique_lock<std::mutex> l(mu);
  cv.wait(l, [&] { return done; });
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNIMPLEMENTED);
  // No registered method: gRPC answers before any interceptor sees a method,
  // or the interceptor counts it; either way nothing stays in flight.
  EXPECT_EQ(MetricSum(metrics::TextExposition(), "kinemo_rpc_in_flight"), 0);
}

TEST(Metrics, OnScrapeValuesAreReadWhenScrapedAndGoneWithTheirRegistration) {
  int sessions = 2;
  auto registration = metrics::OnScrape(
      "kinemo_test_sessions", "test gauge", prometheus::MetricType::Gauge,
      [&](std::vector<metrics::Sample>* out) { out->push_back({{{"robot", "pleo"}}, double(sessions)}); });
  EXPECT_EQ(MetricSum(metrics::TextExposition(), "kinemo_test_sessions", {{"robot", "pleo"}}), 2);
  sessions = 7;
  EXPECT_EQ(MetricSum(metrics::TextExposition(), "kinemo_test_sessions", {{"robot", "pleo"}}), 7);
  registration.reset();
  EXPECT_EQ(metrics::TextExposition().find("kinemo_test_sessions"), std::string::npos);
}

TEST(MetricsEndpoint, ServesTheRegistryOverHttpOnAnEphemeralPort) {
  common::v1::MetricsOptions options;
  options.set_enabled(true);
  auto endpoint = metrics::MetricsEndpoint::Start(options);
  ASSERT_TRUE(endpoint.ok()) << endpoint.status();
  ASSERT_GT((*endpoint)->port(), 0);
  metrics::Counter("kinemo_test_requests_total", "test counter").Increment(3);
  auto body = HttpGet("127.0.0.1", (*endpoint)->port(), "/metrics");
  ASSERT_TRUE(body.ok()) << body.status();
  EXPECT_NE(body->find("# TYPE kinemo_test_requests_total counter"), std::string::npos) << *body;
  EXPECT_GE(MetricSum(*body, "kinemo_test_requests_total"), 3);
  // A second endpoint cannot take the same port: the error names the option.
  options.set_port(static_cast<std::uint32_t>((*endpoint)->port()));
  auto clash = metrics::MetricsEndpoint::Start(options);
  ASSERT_FALSE(clash.ok());
  EXPECT_EQ(clash.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(clash.status().message().find("server.metrics.port"), std::string::npos) << clash.status();
}

TEST(MetricsOptions, FlagsTurnMetricsOnAndBadValuesNameTheirField) {
  const char* argv[] = {"svc", "--metrics-port", "0", "--metrics-port-file", "/tmp/unused"};
  auto command_line = config::ParseServerCommandLine(5, argv, "svc");
  ASSERT_TRUE(command_line.ok()) << command_line.status();
  common::v1::ServerOptions options;
  ASSERT_TRUE(config::LoadServiceOptions(*command_line, &options).ok());
  EXPECT_TRUE(options.metrics().enabled());
  EXPECT_EQ(options.metrics().host(), "127.0.0.1");  // loopback unless told otherwise
  EXPECT_EQ(options.metrics().port(), 0u);

  common::v1::ServerOptions bad = Loopback();
  bad.mutable_metrics()->set_enabled(true);
  bad.mutable_metrics()->set_port(70000);
  auto s = config::ValidateServerOptions(bad);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message().rfind("server.metrics.port", 0), 0u) << s;
  bad.mutable_metrics()->set_port(9000);
  bad.set_port(9000);
  s = config::ValidateServerOptions(bad);
  EXPECT_EQ(s.message().rfind("server.metrics.port", 0), 0u) << s;
  bad.set_port(0);
  bad.mutable_metrics()->set_host("unix:/tmp/m.sock");
  s = config::ValidateServerOptions(bad);
  EXPECT_EQ(s.message().rfind("server.metrics.host", 0), 0u) << s;
}

}  // namespace
}  // namespace kinemo::server
