// IDMS_CHECK: an always-on invariant check for broken invariants (bugs), never for input errors.
#pragma once

namespace idms::internal {
[[noreturn]] void CheckFailed(const char* expr, const char* file, int line);
}  // namespace idms::internal

#define IDMS_CHECK(expr) ((expr) ? static_cast<void>(0) : ::idms::internal::CheckFailed(#expr, __FILE__, __LINE__))
