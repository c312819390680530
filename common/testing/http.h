// Plain HTTP/1.0 GET for tests (a service's GET /metrics), and reading one
// metric out of Prometheus' text exposition format.
#pragma once

#include <chrono>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "common/status/status.h"

namespace kinemo::testing {

// GET http://host:port/path; the body of a 200 answer. UNAVAILABLE when the
// connection fails, INTERNAL for another status line.
StatusOr<std::string> HttpGet(const std::string& host, int port, const std::string& path,
                              std::chrono::milliseconds timeout = std::chrono::milliseconds(5000));

// The sum of every sample of metric `name` (exactly that name: a histogram's
// `_count` or `_sum` is named in full) whose labels include all of `labels`.
// 0 when there is none.
double MetricSum(std::string_view exposition, std::string_view name,
                 const std::vector<std::pair<std::string, std::string>>& labels = {});

}  // namespace kinemo::testing
