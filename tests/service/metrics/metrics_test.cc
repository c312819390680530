// RPC metrics counted by the one interceptor every ServiceHost installs,
// values read at scrape time (OnScrape), the /metrics HTTP endpoint, and the
// metrics options' validation; HTTPS with a client certificate (the
// deploy/certs.sh material) and the bearer token, scraped with curl.
#include <gtest/gtest.h>

#include <condition_variable>
#include <fstream>
#include <functional>
#include <iterator>
#include <mutex>

#include <grpcpp/create_channel.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/security/credentials.h>

#include "common/config/options.h"
#include "common/metrics/metrics.h"
#include "common/server/rpc_metrics.h"
#include "common/server/service_host.h"
#include "common/testing/http.h"
#include "common/testing/process.h"
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

// curl's answer to GET `url` with `flags`: the HTTP status code ("000" when
// no HTTP answer came: a refused handshake), the body in *body.
std::string Curl(const std::string& url, const std::vector<std::string>& flags, std::string* body = nullptr) {
  kinemo::testing::TempDir dir;
  std::vector<std::string> argv = {"/usr/bin/env", "curl", "-s", "--max-time", "5", "-o", dir.File("body"), "-w", "%{http_code}"};
  argv.insert(argv.end(), flags.begin(), flags.end());
  argv.push_back(url);
  std::string out;
  auto code = kinemo::testing::ChildProcess::Run(argv, dir.File("log"), std::chrono::seconds(20), &out);
  EXPECT_TRUE(code.ok()) << code.status();
  if (body != nullptr) {
    std::ifstream in(dir.File("body"));
    body->assign(std::istreambuf_iterator<char>(in), {});
  }
  return out.substr(0, 3);
}

class MetricsTls : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    certs_ = new kinemo::testing::TempDir();
    std::string out;
    auto code = kinemo::testing::ChildProcess::Run(
        {"/usr/bin/env", "bash", std::string(KINEMO_SOURCE_DIR) + "/deploy/certs.sh", "--test-extras", certs_->path()},
        certs_->File("certs.log"), std::chrono::seconds(120), &out);
    ASSERT_TRUE(code.ok() && *code == 0) << out;
  }
  static void TearDownTestSuite() { delete certs_; }
  static std::string Cert(const std::string& name) { return certs_->File(name); }
  static std::vector<std::string> As(const std::string& client) {
    std::vector<std::string> f = {"--cacert", Cert("ca.pem")};
    if (!client.empty()) {
      f.insert(f.end(), {"--cert", Cert(client + ".pem"), "--key", Cert(client + ".key")});
    }
    return f;
  }
  static common::v1::MetricsOptions Tls(bool client_ca) {
    common::v1::MetricsOptions o;
    o.set_enabled(true);
    o.mutable_tls()->set_cert_file(Cert("prosody.pem"));
    o.mutable_tls()->set_key_file(Cert("prosody.key"));
    if (client_ca) o.mutable_tls()->set_client_ca_file(Cert("ca.pem"));
    return o;
  }
  static kinemo::testing::TempDir* certs_;
};
kinemo::testing::TempDir* MetricsTls::certs_ = nullptr;

TEST_F(MetricsTls, HttpsAsksForAClientCertificateFromTheCa) {
  auto endpoint = metrics::MetricsEndpoint::Start(Tls(true));
  ASSERT_TRUE(endpoint.ok()) << endpoint.status();
  metrics::Counter("kinemo_test_tls_scrapes_total", "test counter").Increment();
  const std::string url = "https://127.0.0.1:" + std::to_string((*endpoint)->port()) + "/metrics";
  std::string body;
  EXPECT_EQ(Curl(url, As("prometheus"), &body), "200");
  EXPECT_NE(body.find("# TYPE kinemo_test_tls_scrapes_total counter"), std::string::npos) << body;
  // Refused during the handshake: no certificate, another CA's, an expired one.
  EXPECT_EQ(Curl(url, As("")), "000");
  EXPECT_EQ(Curl(url, As("stranger")), "000");
  EXPECT_EQ(Curl(url, As("expired")), "000");
  // Plain HTTP on the HTTPS port gets no metrics.
  auto plain = HttpGet("127.0.0.1", (*endpoint)->port(), "/metrics");
  EXPECT_FALSE(plain.ok());
  // The endpoint still serves after the refusals.
  EXPECT_EQ(Curl(url, As("cli")), "200");
}

TEST_F(MetricsTls, TheBearerTokenIsAskedOverHttpsAndHttp) {
  const std::string token_file = Cert("metrics-token");
  std::ofstream(token_file) << "  s3cret-token-0123456789abcdef\n";
  for (bool tls : {true, false}) {
    SCOPED_TRACE(tls ? "https" : "http");
    common::v1::MetricsOptions o = tls ? Tls(false) : common::v1::MetricsOptions();
    o.set_enabled(true);
    o.set_bearer_token_file(token_file);
    auto endpoint = metrics::MetricsEndpoint::Start(o);
    ASSERT_TRUE(endpoint.ok()) << endpoint.status();
    // Something to serve (ctest runs each case in a process of its own).
    metrics::Counter("kinemo_test_token_scrapes_total", "test counter").Increment();
    const std::string base =
        std::string(tls ? "https" : "http") + "://127.0.0.1:" + std::to_string((*endpoint)->port());
    std::vector<std::string> flags = tls ? As("") : std::vector<std::string>{};
    auto with = [&](const std::string& header) {
      std::vector<std::string> f = flags;
      f.insert(f.end(), {"-H", header});
      return f;
    };
    std::string body;
    EXPECT_EQ(Curl(base + "/metrics", flags, &body), "401");
    EXPECT_EQ(body.find("kinemo_"), std::string::npos) << body;
    EXPECT_EQ(Curl(base + "/metrics", with("Authorization: Bearer wrong")), "401");
    EXPECT_EQ(Curl(base + "/metrics", with("Authorization: Bearer s3cret-token-0123456789abcde")), "401");
    EXPECT_EQ(Curl(base + "/metrics", with("Authorization: Basic czNjcmV0")), "401");
    EXPECT_EQ(Curl(base + "/metrics", with("Authorization: Bearer s3cret-token-0123456789abcdef"), &body), "200");
    EXPECT_NE(body.find("# TYPE kinemo_test_token_scrapes_total counter"), std::string::npos) << body;
    EXPECT_EQ(Curl(base + "/other", with("Authorization: Bearer s3cret-token-0123456789abcdef")), "404");
    // Without the token nothing else is told either.
    EXPECT_EQ(Curl(base + "/other", flags), "401");
  }
}

TEST_F(MetricsTls, UnusableFilesNameTheirOption) {
  struct Case {
    std::function<void(common::v1::MetricsOptions*)> edit;
    std::string field;
  };
  const std::string not_pem = Cert("not.pem");
  std::ofstream(not_pem) << "not a certificate\n";
  std::ofstream(Cert("empty-token")) << " \n";
  const std::vector<Case> cases = {
      {[](auto* o) { o->mutable_tls()->clear_key_file(); }, "server.metrics.tls.key_file"},
      {[&](auto* o) { o->mutable_tls()->set_cert_file(not_pem); }, "server.metrics.tls.cert_file"},
      {[&](auto* o) { o->mutable_tls()->set_cert_file(Cert("missing.pem")); }, "server.metrics.tls.cert_file"},
      {[&](auto* o) { o->mutable_tls()->set_key_file(Cert("planner.key")); }, "server.metrics.tls.key_file"},
      {[&](auto* o) { o->mutable_tls()->set_client_ca_file(not_pem); }, "server.metrics.tls.client_ca_file"},
      {[&](auto* o) { o->set_bearer_token_file(Cert("empty-token")); }, "server.metrics.bearer_token_file"},
  };
  for (const Case& c : cases) {
    common::v1::MetricsOptions o = Tls(true);
    c.edit(&o);
    auto endpoint = metrics::MetricsEndpoint::Start(o);
    ASSERT_FALSE(endpoint.ok()) << c.field;
    EXPECT_EQ(endpoint.status().code(), absl::StatusCode::kInvalidArgument) << endpoint.status();
    EXPECT_EQ(endpoint.status().message().rfind(c.field, 0), 0u) << endpoint.status();
  }
  // The options' validation names them before a server starts.
  common::v1::ServerOptions bad = Loopback();
  *bad.mutable_metrics() = Tls(true);
  bad.mutable_metrics()->mutable_tls()->clear_cert_file();
  auto s = config::ValidateServerOptions(bad);
  EXPECT_EQ(s.message().rfind("server.metrics.tls.cert_file", 0), 0u) << s;
  *bad.mutable_metrics() = Tls(true);
  bad.mutable_metrics()->set_bearer_token_file(Cert("missing-token"));
  s = config::ValidateServerOptions(bad);
  EXPECT_EQ(s.message().rfind("server.metrics.bearer_token_file", 0), 0u) << s;
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
