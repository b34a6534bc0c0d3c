// ThreadOwner's violation path, out of line: the check itself stays inline and small.
#include "idms/agent/thread_owner.h"

#include <cstdio>
#include <cstdlib>

namespace idms::agent {

void ThreadOwner::Violated(const char* call) noexcept {
  violations_.fetch_add(1, std::memory_order_relaxed);
  if (on_ == OnViolation::kCount) return;
  std::fprintf(stderr, "idms-agent: BUG: %s called from a thread that does not own %s\n", call, what_);
  std::abort();
}

}  // namespace idms::agent
