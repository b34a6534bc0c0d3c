// Counts heap allocations in a test executable that compiles alloc_counter.cc (sim_tests,
// agent_tests): it replaces the global operator new so a test can prove a region allocates nothing.
#pragma once

#include <cstdint>

namespace idms::test {

// Calls of any global operator new since the program started (all threads).
int64_t AllocationCount();

}  // namespace idms::test
