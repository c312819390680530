// The online filter allocates nothing per step: counts global operator new
// calls while stepping.
#include <atomic>
#include <cstdlib>
#include <new>
#include <random>

#include <gtest/gtest.h>

#include "services/inference/core/remapped_model.h"
#include "tests/unit/inference/planted.h"

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
}  // namespace

// GCC at -O1 (test code compiles as glue) inlines gtest's `new TestClass`
// and then takes the free() below for a mismatch with its own operator new;
// both are these replacements.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t size) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace kinemo::inference {
namespace {

TEST(OnlineFilterTest, NoAllocationPerStep) {
  testing::PlantedPipeline planted(5, 0, 3);
  std::mt19937_64 rng(1);
  std::vector<PairedSequence> train{planted.Sample(300, rng, nullptr),
                                    planted.Sample(300, rng, nullptr)};
  ModelTrainParams p;
  p.num_states = 5;
  p.window = 4;
  p.num_clusters = 10;
  p.hmm_restarts = 1;
  auto model = RemappedModel::Train(train, p, nullptr, nullptr);
  ASSERT_TRUE(model.ok()) << model.status();
  const PairedSequence test = planted.Sample(500, rng, nullptr);
  OnlineFilter filter(*model);
  std::vector<double> alpha(5);
  int emitted = 0;
  g_allocations = 0;
  g_counting = true;
  for (const auto& x : test.inputs) emitted += filter.Push(x, alpha) ? 1 : 0;
  while (filter.Finish(alpha)) ++emitted;
  g_counting = false;
  EXPECT_EQ(g_allocations.load(), 0);
  EXPECT_EQ(emitted, 500);
}

}  // namespace
}  // namespace kinemo::inference
