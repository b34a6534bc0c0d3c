// Counts heap allocations in sim_tests: alloc_counter_test.cc replaces the global operator new
// (the only replacement in this executable) so a test can prove a region allocates nothing.
#pragma once

#include <cstdint>

namespace idms::test {

// Calls of any global operator new since the program started (all threads).
int64_t AllocationCount();

}  // namespace idms::test
