// libFuzzer target: the agent's UDP bridge (protocol/udp_bridge.md). Any datagram decodes or is
// refused; what decodes is finite (an orientation nonzero), and encodes back to the same bytes.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "idms/agent/udp_bridge.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace idms::agent;
  UdpPosition p;
  if (DecodeUdpPosition(data, size, &p)) {
    for (double v : p.pos) {
      if (!std::isfinite(v)) std::abort();
    }
    if (p.oriented) {
      double norm = 0;
      for (double v : p.orientation) norm += v * v;
      if (!std::isfinite(norm) || !(norm > 0)) std::abort();
    }
    uint8_t again[kUdpMaxDatagramBytes];
    const size_t n = EncodeUdpPosition(p, again);
    // The reserved word (12..15) is written as 0; every other byte is the datagram's.
    if (n != size || std::memcmp(again, data, 12) != 0 || std::memcmp(again + 16, data + 16, n - 16) != 0) std::abort();
  }
  UdpForce f;
  if (DecodeUdpForce(data, size, &f)) {
    for (double v : f.force) {
      if (!std::isfinite(v)) std::abort();
    }
    uint8_t again[kUdpDatagramBytes];
    EncodeUdpForce(f, again);
    if (size != kUdpDatagramBytes || std::memcmp(again, data, size) != 0) std::abort();
  }
  return 0;
}
