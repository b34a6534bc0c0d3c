// A check that AllocationCount() (tests/common/alloc_counter.cc) counts every form of new.
#include "alloc_counter.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <memory>
#include <new>
#include <vector>

namespace idms::test {
namespace {

TEST(AllocCounter, CountsVectorAndMakeUnique) {
  const int64_t before = AllocationCount();
  std::vector<int> v(16);
  auto p = std::make_unique<double[]>(4);
  asm volatile("" : : "g"(v.data()), "g"(p.get()) : "memory");  // keep both allocations
  EXPECT_GE(AllocationCount() - before, 2);
  const int64_t mid = AllocationCount();
  v[0] = 1;
  p[0] = 2;
  EXPECT_EQ(AllocationCount(), mid);
}

}  // namespace
}  // namespace idms::test
