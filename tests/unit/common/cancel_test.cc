// CancelToken (common/status/cancel.h): the plain token core loops poll.
#include "common/status/cancel.h"

#include <atomic>
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

namespace kinemo {
namespace {

using Clock = CancelToken::Clock;

TEST(CancelToken, NeverStopsUntilCancelled) {
  EXPECT_TRUE(CheckCancel(nullptr, "work").ok());
  EXPECT_FALSE(Stopped(nullptr));
  CancelToken t;
  EXPECT_TRUE(t.Check("work").ok());
  t.Cancel();
  const Status s = t.Check("value iteration");
  EXPECT_EQ(s.code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(s.message().substr(0, 16), "value iteration:");
}

TEST(CancelToken, StopsAtItsDeadline) {
  CancelToken past(Clock::now() - std::chrono::milliseconds(1));
  EXPECT_TRUE(past.stopped());
  EXPECT_EQ(past.Check("analysis").code(), absl::StatusCode::kDeadlineExceeded);
  CancelToken future(Clock::now() + std::chrono::hours(1));
  EXPECT_FALSE(future.stopped());
  EXPECT_TRUE(future.Check("analysis").ok());
}

// The probe (the RPC's own cancellation) is polled, from any thread.
TEST(CancelToken, FollowsItsProbeFromOtherThreads) {
  std::atomic<bool> flag{false};
  CancelToken t(Clock::time_point::max(), [&] { return flag.load(); });
  EXPECT_FALSE(t.stopped());
  flag = true;
  std::atomic<bool> seen{false};
  std::thread worker([&] { seen = Stopped(&t); });
  worker.join();
  EXPECT_TRUE(seen);
  EXPECT_EQ(t.Check("build").code(), absl::StatusCode::kCancelled);
}

}  // namespace
}  // namespace kinemo
