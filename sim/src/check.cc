// The failure path of IDMS_CHECK: print where, then abort.
#include "idms/sim/check.h"

#include <cstdio>
#include <cstdlib>

namespace idms::internal {

void CheckFailed(const char* expr, const char* file, int line) {
  std::fprintf(stderr, "%s:%d: IDMS_CHECK failed: %s\n", file, line, expr);
  std::abort();
}

}  // namespace idms::internal
