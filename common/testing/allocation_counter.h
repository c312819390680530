// Counts global operator new calls while `AllocationCounter::Counting` is
// set: for tests that check a hot loop allocates nothing. Replaces the global
// allocator, so include it in exactly one source file of a test binary.
#pragma once

#include <atomic>
#include <cstdlib>
#include <new>

namespace kinemo::testing {

struct AllocationCounter {
  static inline std::atomic<bool> counting{false};
  static inline std::atomic<long> allocations{0};

  // Runs `f` and returns the number of allocations it made.
  template <typename F>
  static long Count(F&& f) {
    allocations = 0;
    counting = true;
    f();
    counting = false;
    return allocations.load();
  }
};

}  // namespace kinemo::testing

// GCC cannot see that the replaced new and delete match.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t size) {
  if (kinemo::testing::AllocationCounter::counting.load(std::memory_order_relaxed)) {
    kinemo::testing::AllocationCounter::allocations.fetch_add(1);
  }
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
