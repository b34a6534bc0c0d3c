// Counts heap allocations in agent_tests: alloc_counter.cc replaces the global operator new
// (the only replacement in this executable) so a test can prove the loop's tick allocates nothing.
#pragma once

#include <cstdint>

namespace idms::test {

// Calls of any global operator new since the program started (all threads).
int64_t AllocationCount();

}  // namespace idms::test
