// Time as the coordinator's core sees it: a monotonic clock for the emotion
// model and a wall clock for event timestamps. Injectable, so that tests run
// the model deterministically and instantly (FakeClock).
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>

namespace kinemo::coordinator {

class Clock {
 public:
  virtual ~Clock() = default;
  // Monotonic time, in seconds from an arbitrary origin.
  virtual double MonotonicS() const = 0;
  // Wall-clock time, in nanoseconds since the Unix epoch.
  virtual std::int64_t WallUnixNs() const = 0;
};

// steady_clock and system_clock.
class SystemClock final : public Clock {
 public:
  double MonotonicS() const override {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }
  std::int64_t WallUnixNs() const override {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  }
  // A process-wide instance.
  static SystemClock* Get() {
    static SystemClock clock;
    return &clock;
  }
};

// A clock that moves only when told to (both readings move together).
class FakeClock final : public Clock {
 public:
  explicit FakeClock(double start_s = 1000.0, std::int64_t wall_start_ns = 1'700'000'000'000'000'000)
      : now_s_(start_s), start_s_(start_s), wall_start_ns_(wall_start_ns) {}
  double MonotonicS() const override {
    std::lock_guard<std::mutex> l(mu_);
    return now_s_;
  }
  std::int64_t WallUnixNs() const override {
    std::lock_guard<std::mutex> l(mu_);
    return wall_start_ns_ + static_cast<std::int64_t>((now_s_ - start_s_) * 1e9);
  }
  void Advance(double seconds) {
    std::lock_guard<std::mutex> l(mu_);
    now_s_ += seconds;
  }

 private:
  mutable std::mutex mu_;
  double now_s_;
  double start_s_;
  std::int64_t wall_start_ns_;
};

}  // namespace kinemo::coordinator
