// The replaced global operator new/delete behind AllocationCount(), and a check that it counts.
#include <atomic>
#include <cstdlib>
#include <memory>
#include <new>
#include <vector>

#include <gtest/gtest.h>

#include "alloc_counter.h"

namespace {
std::atomic<int64_t> g_allocations{0};

void* Allocate(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}

void* AllocateAligned(std::size_t size, std::align_val_t align) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  const std::size_t a = static_cast<std::size_t>(align);
  const std::size_t rounded = (size + a - 1) / a * a;
  if (void* p = std::aligned_alloc(a, rounded == 0 ? a : rounded)) return p;
  throw std::bad_alloc();
}
}  // namespace

// libstdc++ routes new[], nothrow and sized forms through these, so replacing them counts all.
void* operator new(std::size_t size) { return Allocate(size); }
void* operator new[](std::size_t size) { return Allocate(size); }
void* operator new(std::size_t size, std::align_val_t align) { return AllocateAligned(size, align); }
void* operator new[](std::size_t size, std::align_val_t align) { return AllocateAligned(size, align); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

namespace idms::test {
int64_t AllocationCount() { return g_allocations.load(std::memory_order_relaxed); }
}  // namespace idms::test

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
