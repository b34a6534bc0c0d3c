// Wall-clock times and random identifiers for sessions.
#include <openssl/rand.h>

#include <chrono>
#include <ctime>
#include <vector>

#include "idms/protocol/digest.h"
#include "server_internal.h"

namespace idms::server {

uint64_t UnixNs() {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

uint64_t ParseUtcNs(const std::string& iso) {
  std::tm tm{};
  const char* end = strptime(iso.c_str(), "%Y-%m-%dT%H:%M:%SZ", &tm);
  if (end == nullptr || *end != '\0') return 0;
  const time_t t = timegm(&tm);
  return t < 0 ? 0 : static_cast<uint64_t>(t) * 1000000000ull;
}

std::string RandomHex(size_t bytes) {
  std::vector<unsigned char> raw(bytes);
  RAND_bytes(raw.data(), static_cast<int>(raw.size()));
  return HexEncode(raw);
}

}  // namespace idms::server
