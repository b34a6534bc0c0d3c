// String building for messages: Cat({"a", b, "c"}) instead of chains of operator+, which GCC 12
// flags with false -Wrestrict positives when a chain starts with a short literal.
#pragma once

#include <initializer_list>
#include <string>
#include <string_view>

namespace idms::agent {

inline std::string Cat(std::initializer_list<std::string_view> parts) {
  std::string out;
  for (std::string_view p : parts) out.append(p);
  return out;
}

}  // namespace idms::agent
