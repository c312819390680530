// Small helpers the controller's sources share (one definition for the
// unity build, docs/DEVELOPING.md).
#pragma once

#include <chrono>
#include <limits>

namespace kinemo::planner::controller::internal {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

inline double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace kinemo::planner::controller::internal
