#include "common/metrics/metrics.h"

#include <map>
#include <mutex>
#include <sstream>

#include <prometheus/collectable.h>
#include <prometheus/text_serializer.h>

#include "absl/strings/str_cat.h"

namespace kinemo::metrics {

const std::shared_ptr<prometheus::Registry>& Registry() {
  static const auto* registry = new std::shared_ptr<prometheus::Registry>(
      std::make_shared<prometheus::Registry>(prometheus::Registry::InsertBehavior::Merge));
  return *registry;
}

prometheus::Counter& Counter(const std::string& name, const std::string& help,
                             const prometheus::Labels& labels) {
  return prometheus::BuildCounter().Name(name).Help(help).Register(*Registry()).Add(labels);
}

prometheus::Gauge& Gauge(const std::string& name, const std::string& help,
                         const prometheus::Labels& labels) {
  return prometheus::BuildGauge().Name(name).Help(help).Register(*Registry()).Add(labels);
}

prometheus::Histogram& Histogram(const std::string& name, const std::string& help,
                                 const std::vector<double>& buckets,
                                 const prometheus::Labels& labels) {
  return prometheus::BuildHistogram()
      .Name(name)
      .Help(help)
      .Register(*Registry())
      .Add(labels, prometheus::Histogram::BucketBoundaries(buckets));
}

const std::vector<double>& LatencyBucketsS() {
  static const auto* buckets = new std::vector<double>{
      0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120};
  return *buckets;
}

namespace {

// The OnScrape sources, collected beside the registry.
class ScrapeSources final : public prometheus::Collectable {
 public:
  std::uint64_t Add(std::string name, std::string help, prometheus::MetricType type, SampleFn fn) {
    std::lock_guard<std::mutex> lock(mu_);
    const std::uint64_t id = next_id_++;
    sources_.emplace(id, Source{std::move(name), std::move(help), type, std::move(fn)});
    return id;
  }
  void Remove(std::uint64_t id) {
    std::lock_guard<std::mutex> lock(mu_);
    sources_.erase(id);
  }
  std::vector<prometheus::MetricFamily> Collect() const override {
    std::lock_guard<std::mutex> lock(mu_);
    std::map<std::string, prometheus::MetricFamily> families;
    std::vector<Sample> samples;
    for (const auto& [id, source] : sources_) {
      samples.clear();
      source.fn(&samples);
      auto [it, inserted] = families.try_emplace(source.name);
      prometheus::MetricFamily& family = it->second;
      if (inserted) {
        family.name = source.name;
        family.help = source.help;
        family.type = source.type;
      }
      for (const Sample& sample : samples) {
        prometheus::ClientMetric metric;
        for (const auto& [key, value] : sample.labels) metric.label.push_back({key, value});
        if (source.type == prometheus::MetricType::Counter) {
          metric.counter.value = sample.value;
        } else {
          metric.gauge.value = sample.value;
        }
        family.metric.push_back(std::move(metric));
      }
    }
    std::vector<prometheus::MetricFamily> out;
    for (auto& [name, family] : families) {
      if (!family.metric.empty()) out.push_back(std::move(family));
    }
    return out;
  }

 private:
  struct Source {
    std::string name, help;
    prometheus::MetricType type;
    SampleFn fn;
  };
  mutable std::mutex mu_;
  std::uint64_t next_id_ = 1;
  std::map<std::uint64_t, Source> sources_;
};

const std::shared_ptr<ScrapeSources>& Sources() {
  static const auto* sources = new std::shared_ptr<ScrapeSources>(std::make_shared<ScrapeSources>());
  return *sources;
}

}  // namespace

std::unique_ptr<ScrapeRegistration> OnScrape(std::string name, std::string help,
                                             prometheus::MetricType type, SampleFn fn) {
  return std::unique_ptr<ScrapeRegistration>(
      new ScrapeRegistration(Sources()->Add(std::move(name), std::move(help), type, std::move(fn))));
}

ScrapeRegistration::~ScrapeRegistration() { Sources()->Remove(id_); }

std::string TextExposition() {
  std::vector<prometheus::MetricFamily> families = Registry()->Collect();
  for (auto& family : Sources()->Collect()) families.push_back(std::move(family));
  std::ostringstream out;
  prometheus::TextSerializer().Serialize(out, families);
  return out.str();
}

}  // namespace kinemo::metrics
