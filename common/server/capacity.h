// Default capacity of live work, from what this machine holds (measured with
// `kinemo bench load --realtime`, README "Live load"): header-only.
#pragma once

#include <algorithm>
#include <thread>

namespace kinemo::server {

// Live StreamAnimate streams one core carries inside the live targets (motion
// lag p99 ≤ 80 ms, no frame gap over 100 ms) with the bundled 55-joint
// conversational controller: each real-time stream costs about 0.7 % of a
// core, so 64 per core leaves headroom for gRPC and the client's own bursts.
inline constexpr int kLiveStreamsPerCore = 64;

// The default admission limit of live streams: kLiveStreamsPerCore per core
// this process may run on.
inline int DefaultLiveStreamLimit() {
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  return kLiveStreamsPerCore * static_cast<int>(cores);
}

}  // namespace kinemo::server
