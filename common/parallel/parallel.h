// Spreading independent work items over threads, for one call's own use (no
// pool outlives the call). Items are claimed one at a time from a shared
// counter, so uneven items balance themselves; the calling thread works too.
//
// If a thread cannot be started (resource limits), the threads that did start
// and the caller finish the work: the result never depends on the number of
// threads, only the time does.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <system_error>
#include <thread>
#include <vector>

namespace kinemo::parallel {

// Threads to use for `requested` (0 = one per core), at least 1.
inline int ResolveThreads(int requested) {
  if (requested > 0) return requested;
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

// Runs work(item, worker) for every item in [0, items) on up to `threads`
// threads (worker in [0, threads) tells which thread runs the item, e.g. to
// pick its scratch buffers; the caller is worker 0), and consume(item) on the
// calling thread for items 0, 1, 2, ... in order, each as soon as it and every
// item before it are done. consume may be left empty ([](int) {}).
template <typename Work, typename Consume>
void OrderedParallelFor(int items, int threads, const Work& work, const Consume& consume) {
  threads = std::max(1, std::min(threads, items));
  if (threads == 1) {
    for (int i = 0; i < items; ++i) {
      work(i, 0);
      consume(i);
    }
    return;
  }
  std::atomic<int> next{0};
  std::unique_ptr<std::atomic<uint8_t>[]> done(new std::atomic<uint8_t>[static_cast<size_t>(items)]);
  for (int i = 0; i < items; ++i) done[static_cast<size_t>(i)].store(0, std::memory_order_relaxed);
  auto run = [&](int worker) {
    for (int i = next.fetch_add(1); i < items; i = next.fetch_add(1)) {
      work(i, worker);
      done[static_cast<size_t>(i)].store(1, std::memory_order_release);
      done[static_cast<size_t>(i)].notify_all();
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(static_cast<size_t>(threads - 1));
  for (int t = 1; t < threads; ++t) {
    try {
      pool.emplace_back(run, t);
    } catch (const std::system_error&) {
      break;  // fewer threads; the others take the items
    }
  }
  // The caller consumes what is ready, else works, else waits for the next
  // item in order (every item left is then being worked on by a thread).
  int consumed = 0;
  while (consumed < items) {
    std::atomic<uint8_t>& ready = done[static_cast<size_t>(consumed)];
    if (ready.load(std::memory_order_acquire)) {
      consume(consumed++);
      continue;
    }
    const int i = next.fetch_add(1);
    if (i < items) {
      work(i, 0);
      done[static_cast<size_t>(i)].store(1, std::memory_order_release);
    } else {
      ready.wait(0, std::memory_order_acquire);
    }
  }
  for (std::thread& t : pool) t.join();
}

// Runs work(item, worker) for every item in [0, items), as above.
template <typename Work>
void ParallelFor(int items, int threads, const Work& work) {
  OrderedParallelFor(items, threads, work, [](int) {});
}

// Runs work(lo, hi, worker) on `threads` equal contiguous ranges of [0, n)
// (range t = [n·t/threads, n·(t+1)/threads), worker t), each on its own thread
// (just the caller when threads or n is 1): for loops whose items are too
// small to claim one at a time. The split depends only on n and threads.
template <typename Work>
void ParallelForRanges(int n, int threads, const Work& work) {
  threads = std::max(1, std::min(threads, n));
  if (threads == 1) {
    if (n > 0) work(0, n, 0);
    return;
  }
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) {
    const int lo = static_cast<int>(static_cast<long>(n) * t / threads);
    const int hi = static_cast<int>(static_cast<long>(n) * (t + 1) / threads);
    pool.emplace_back([&work, lo, hi, t] { work(lo, hi, t); });
  }
  for (auto& th : pool) th.join();
}

}  // namespace kinemo::parallel
