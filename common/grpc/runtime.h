// Process-wide settings for the gRPC runtime kinemo links against.
#pragma once

#include "absl/synchronization/mutex.h"

namespace kinemo {

// Debian builds Abseil without NDEBUG, so every absl::Mutex (and gRPC locks
// through it) records its lock order in a global graph to detect deadlock
// cycles, a debugging aid that optimised Abseil builds leave off. Turned off
// here as in those builds: at 128 live streams it was 1.5 % of the all-in-one's
// CPU (GraphCycles, perf). Call once early in main (or before serving).
inline void UseReleaseLockChecks() { absl::SetMutexDeadlockDetectionMode(absl::OnDeadlockCycle::kIgnore); }

}  // namespace kinemo
