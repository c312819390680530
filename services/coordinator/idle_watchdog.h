// The idle timeout of the coordinator's downstream streams
// (CoordinatorOptions.deadlines.stream_idle_s): one thread polls every
// registered check at a fixed period, and a check that finds its stream
// idle cancels it. StreamAnimate registers one check per stream (its three
// legs, stream_animate.cc); the synchronous streams (the robot bridge's
// WatchStatus, the cube tracker's TrackSource) use an IdleGuard.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include <grpcpp/client_context.h>

namespace kinemo::coordinator {

class Watchdog {
 public:
  using Clock = std::chrono::steady_clock;
  // Called every period with the time; returns false to be forgotten.
  // Called on the watchdog's thread with none of its locks held (a check
  // may take its stream's lock; Add may be called under that lock).
  using Check = std::function<bool(Clock::time_point now)>;

  // Polls every `period` (the precision of the timeouts).
  explicit Watchdog(Clock::duration period);
  ~Watchdog();
  void Add(Check check);
  // Stops the thread (idempotent); checks are forgotten.
  void Stop();
  // The period for an idle timeout of `idle_s`: a tenth of it, in [10 ms, 250 ms].
  static Clock::duration PeriodFor(double idle_s);

 private:
  void Run();

  const Clock::duration period_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::vector<Check> added_;  // guarded by mu_; moved to the thread's own list
  std::thread thread_;
};

// The idle timeout of one synchronous client stream: Touch() on every
// message received; when none came for `idle_s`, the call is cancelled
// (its Finish() then says CANCELLED) and expired() is true, which the
// caller reports as DEADLINE_EXCEEDED. Make it after the call's context and
// destroy it before (the destructor stops watching).
class IdleGuard {
 public:
  // `watchdog` null = no timeout.
  IdleGuard(Watchdog* watchdog, grpc::ClientContext* context, double idle_s);
  ~IdleGuard();
  IdleGuard(const IdleGuard&) = delete;
  IdleGuard& operator=(const IdleGuard&) = delete;
  void Touch();
  bool expired() const;

 private:
  struct State {
    std::mutex mu;
    grpc::ClientContext* context = nullptr;  // null once done
    std::atomic<std::int64_t> last_ns{0};    // steady clock
    bool expired = false;
  };
  std::shared_ptr<State> state_;
};

}  // namespace kinemo::coordinator
