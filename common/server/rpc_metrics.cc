#include "common/server/rpc_metrics.h"

#include <array>
#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

#include <grpcpp/support/status.h>

#include "absl/strings/str_cat.h"
#include "common/metrics/metrics.h"

namespace kinemo::server {
namespace {

constexpr int kCodes = 17;  // grpc::StatusCode OK … UNAUTHENTICATED

const char* CodeName(int code) {
  static constexpr std::array<const char*, kCodes> kNames = {
      "OK",          "CANCELLED",         "UNKNOWN",           "INVALID_ARGUMENT",
      "DEADLINE_EXCEEDED", "NOT_FOUND",   "ALREADY_EXISTS",    "PERMISSION_DENIED",
      "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION", "ABORTED",  "OUT_OF_RANGE",
      "UNIMPLEMENTED", "INTERNAL",        "UNAVAILABLE",       "DATA_LOSS",
      "UNAUTHENTICATED"};
  return kNames[static_cast<std::size_t>(code)];
}

// The metrics of one method; per-code series are made on the first call
// that ends with that code.
class MethodMetrics {
 public:
  explicit MethodMetrics(std::string method)
      : method_(std::move(method)),
        started_(metrics::Counter("kinemo_rpc_started_total", "RPCs started, by method.",
                                  {{"method", method_}})),
        in_flight_(metrics::Gauge("kinemo_rpc_in_flight", "RPCs running now, by method.",
                                  {{"method", method_}})) {}

  void Start() {
    started_.Increment();
    in_flight_.Increment();
  }
  void Finish(int code, double seconds) {
    in_flight_.Decrement();
    if (code < 0 || code >= kCodes) code = static_cast<int>(grpc::StatusCode::UNKNOWN);
    Series* series = series_[static_cast<std::size_t>(code)].load(std::memory_order_acquire);
    if (series == nullptr) series = MakeSeries(code);
    series->handled.Increment();
    series->seconds.Observe(seconds);
  }

 private:
  struct Series {
    prometheus::Counter& handled;
    prometheus::Histogram& seconds;
  };
  Series* MakeSeries(int code) {
    std::lock_guard<std::mutex> lock(mu_);
    auto& slot = series_[static_cast<std::size_t>(code)];
    if (Series* existing = slot.load(std::memory_order_acquire)) return existing;
    const prometheus::Labels labels = {{"method", method_}, {"code", CodeName(code)}};
    owned_[static_cast<std::size_t>(code)] = std::make_unique<Series>(Series{
        metrics::Counter("kinemo_rpc_handled_total", "RPCs finished, by method and status code.", labels),
        metrics::Histogram("kinemo_rpc_handling_seconds",
                           "Time from an RPC's start to its status, by method and status code.",
                           metrics::LatencyBucketsS(), labels)});
    slot.store(owned_[static_cast<std::size_t>(code)].get(), std::memory_order_release);
    return owned_[static_cast<std::size_t>(code)].get();
  }

  const std::string method_;
  prometheus::Counter& started_;
  prometheus::Gauge& in_flight_;
  std::mutex mu_;
  std::array<std::atomic<Series*>, kCodes> series_{};
  std::array<std::unique_ptr<Series>, kCodes> owned_;
};

struct StringHash {
  using is_transparent = void;
  std::size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
};

// Every method seen by any server of the process (shared: the metrics are
// the process' too). Entries live as long as the process.
class MethodTable {
 public:
  MethodMetrics& Get(const char* method) {
    const std::string_view name = method == nullptr || *method == '\0' ? "unknown" : method;
    std::lock_guard<std::mutex> lock(mu_);
    auto it = methods_.find(name);
    if (it != methods_.end()) return *it->second;
    if (methods_.size() >= static_cast<std::size_t>(kMaxMethods)) name_other_ = true;
    const std::string key = name_other_ ? std::string("other") : std::string(name);
    auto [slot, inserted] = methods_.try_emplace(key, nullptr);
    if (inserted) slot->second = std::make_unique<MethodMetrics>(key);
    return *slot->second;
  }

 private:
  std::mutex mu_;
  bool name_other_ = false;
  std::unordered_map<std::string, std::unique_ptr<MethodMetrics>, StringHash, std::equal_to<>> methods_;
};

MethodTable& Methods() {
  static auto* table = new MethodTable();
  return *table;
}

class RpcMetricsInterceptor final : public grpc::experimental::Interceptor {
 public:
  explicit RpcMetricsInterceptor(grpc::experimental::ServerRpcInfo* info)
      : metrics_(Methods().Get(info->method())), start_(std::chrono::steady_clock::now()) {
    metrics_.Start();
  }
  ~RpcMetricsInterceptor() override {
    // A call that ends without sending a status was cancelled (client gone,
    // deadline, server shutdown).
    if (!finished_) Finish(static_cast<int>(grpc::StatusCode::CANCELLED));
  }

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            grpc::experimental::InterceptionHookPoints::PRE_SEND_STATUS)) {
      Finish(static_cast<int>(methods->GetSendStatus().error_code()));
    }
    methods->Proceed();
  }

 private:
  void Finish(int code) {
    if (finished_) return;
    finished_ = true;
    metrics_.Finish(code, std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
  }

  MethodMetrics& metrics_;
  const std::chrono::steady_clock::time_point start_;
  bool finished_ = false;
};

class RpcMetricsFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    return new RpcMetricsInterceptor(info);
  }
};

}  // namespace

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeRpcMetricsInterceptorFactory() {
  return std::make_unique<RpcMetricsFactory>();
}

}  // namespace kinemo::server
