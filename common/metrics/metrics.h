// Prometheus metrics of a kinemo process (prometheus-cpp, pull model).
//
// One registry per process: every service in it (the all-in-one hosts them
// all) adds its metrics there, and one HTTP endpoint (MetricsEndpoint,
// started by the server bootstrap from ServerOptions.metrics) serves them as
// `GET /metrics`. Metrics are created once, when a service is built, and
// kept as references: updating a counter, gauge or histogram is lock-free
// and allocates nothing. Names follow Prometheus' conventions (`kinemo_`
// prefix, `_total` for counters, base units: `_seconds`). docs/deploy.md
// "Scaling out" lists them. No gRPC here (core libraries may use it).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <prometheus/counter.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/labels.h>
#include <prometheus/metric_type.h>
#include <prometheus/registry.h>

#include "common/status/status.h"
#include "kinemo/common/v1/server.pb.h"

namespace kinemo::metrics {

// The process-wide registry.
const std::shared_ptr<prometheus::Registry>& Registry();

// The metric `name` with `labels`, created on first use (later calls with the
// same name and labels return the same object; help is taken from the first).
prometheus::Counter& Counter(const std::string& name, const std::string& help,
                             const prometheus::Labels& labels = {});
prometheus::Gauge& Gauge(const std::string& name, const std::string& help,
                         const prometheus::Labels& labels = {});
// `buckets`: upper bounds in increasing order (used when first created).
prometheus::Histogram& Histogram(const std::string& name, const std::string& help,
                                 const std::vector<double>& buckets,
                                 const prometheus::Labels& labels = {});

// Bucket bounds for latencies of calls, 1 ms … 120 s.
const std::vector<double>& LatencyBucketsS();

// A value read when scraped, for state a service already keeps (a session
// count, a robot's link state) rather than updating a gauge on every change.
struct Sample {
  prometheus::Labels labels;
  double value = 0;
};
using SampleFn = std::function<void(std::vector<Sample>* out)>;

// Registers `fn` as the source of metric `name` (type kGauge or kCounter)
// until the returned handle is destroyed; it must not outlive what `fn`
// reads. Several registrations of one name (two coordinators in one test
// process) are merged into one family. `fn` runs on the scraping thread.
class ScrapeRegistration;
std::unique_ptr<ScrapeRegistration> OnScrape(std::string name, std::string help,
                                             prometheus::MetricType type, SampleFn fn);
class ScrapeRegistration {
 public:
  ~ScrapeRegistration();
  ScrapeRegistration(const ScrapeRegistration&) = delete;
  ScrapeRegistration& operator=(const ScrapeRegistration&) = delete;

 private:
  friend std::unique_ptr<ScrapeRegistration> OnScrape(std::string, std::string,
                                                      prometheus::MetricType, SampleFn);
  explicit ScrapeRegistration(std::uint64_t id) : id_(id) {}
  std::uint64_t id_;
};

// Every metric of the process in the text exposition format (what
// GET /metrics answers), e.g. for tests and `kinemo` tools in process.
std::string TextExposition();

// `GET /metrics` over HTTP, or HTTPS with options.tls, for the process'
// registry and OnScrape values (endpoint.cc; Boost.Beast, one thread).
// options.tls.client_ca_file: the client must present a certificate from that
// CA (else the handshake fails); options.bearer_token_file: every request needs
// `Authorization: Bearer <the file's token>` (else 401, nothing served).
class MetricsEndpoint {
 public:
  // Listens on options.host:options.port (port 0 = ephemeral; host empty =
  // 127.0.0.1). UNAVAILABLE naming "server.metrics.port" when it cannot bind;
  // INVALID_ARGUMENT naming "server.metrics.tls.<file>" or
  // "server.metrics.bearer_token_file" when a file cannot be read or used.
  static StatusOr<std::unique_ptr<MetricsEndpoint>> Start(const common::v1::MetricsOptions& options);
  ~MetricsEndpoint();
  MetricsEndpoint(const MetricsEndpoint&) = delete;
  MetricsEndpoint& operator=(const MetricsEndpoint&) = delete;

  // The bound port and "host:port".
  int port() const { return port_; }
  const std::string& address() const { return address_; }

  struct Impl;

 private:
  MetricsEndpoint() = default;
  std::unique_ptr<Impl> impl_;
  int port_ = 0;
  std::string address_;
};

}  // namespace kinemo::metrics
