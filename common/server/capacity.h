// Default capacity of live work, from what this machine holds (measured with
// `kinemo bench load --realtime`, docs/benchmarks.md "Live load"): header-only.
#pragma once

#include <algorithm>
#include <thread>

namespace kinemo::server {

// Live StreamAnimate streams one core carries inside the live targets (motion
// lag p99 ≤ 80 ms, no frame gap over 100 ms) with the bundled 55-joint
// conversational controller. Measured on a 2-core machine, all-in-one and
// `kinemo bench load --realtime` (its client on the same cores, ~0.5 core):
// 96 streams kept lag p99 at 15-65 ms; 128 fell behind (p99 0.4-1.5 s) at
// ~1.1 % of a core per stream. So 48 per core.
inline constexpr int kLiveStreamsPerCore = 48;

// The default admission limit of live streams: kLiveStreamsPerCore per core
// this process may run on.
inline int DefaultLiveStreamLimit() {
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  return kLiveStreamsPerCore * static_cast<int>(cores);
}

}  // namespace kinemo::server
