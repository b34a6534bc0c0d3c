// Little-endian packing of the UDP bridge datagrams (layout in protocol/udp_bridge.md).
#include "idms/agent/udp_bridge.h"

#include <bit>
#include <cmath>

namespace idms::agent {
namespace {

// Byte-wise so the wire order is little-endian whatever the host's.
template <typename T>
void Put(uint8_t* out, size_t offset, T value) {
  for (size_t i = 0; i < sizeof(T); ++i) out[offset + i] = static_cast<uint8_t>(value >> (8 * i));
}

template <typename T>
T Get(const uint8_t* data, size_t offset) {
  T value = 0;
  for (size_t i = 0; i < sizeof(T); ++i) value |= static_cast<T>(static_cast<T>(data[offset + i]) << (8 * i));
  return value;
}

void PutDouble(uint8_t* out, size_t offset, double v) { Put<uint64_t>(out, offset, std::bit_cast<uint64_t>(v)); }
double GetDouble(const uint8_t* data, size_t offset) { return std::bit_cast<double>(Get<uint64_t>(data, offset)); }

// Common header: magic (0), version (4), flags (6), sequence (8).
bool CheckHeader(const uint8_t* data, size_t size, uint32_t magic) {
  return size == kUdpDatagramBytes && Get<uint32_t>(data, 0) == magic && Get<uint16_t>(data, 4) == kUdpBridgeVersion;
}

}  // namespace

size_t EncodeUdpPosition(const UdpPosition& msg, uint8_t out[kUdpMaxDatagramBytes]) {
  Put<uint32_t>(out, 0, kUdpPositionMagic);
  Put<uint16_t>(out, 4, msg.oriented ? kUdpOrientedVersion : kUdpBridgeVersion);
  Put<uint16_t>(out, 6, msg.flags);
  Put<uint32_t>(out, 8, msg.sequence);
  Put<uint32_t>(out, 12, 0);
  Put<uint64_t>(out, 16, msg.driver_time_ns);
  for (size_t i = 0; i < 3; ++i) PutDouble(out, 24 + 8 * i, msg.pos[i]);
  if (!msg.oriented) return kUdpDatagramBytes;
  for (size_t i = 0; i < 4; ++i) PutDouble(out, 48 + 8 * i, msg.orientation[i]);
  return kUdpOrientedBytes;
}

void EncodeUdpForce(const UdpForce& msg, uint8_t out[kUdpDatagramBytes]) {
  Put<uint32_t>(out, 0, kUdpForceMagic);
  Put<uint16_t>(out, 4, kUdpBridgeVersion);
  Put<uint16_t>(out, 6, msg.flags);
  Put<uint32_t>(out, 8, msg.sequence);
  Put<uint32_t>(out, 12, msg.echo_sequence);
  Put<uint64_t>(out, 16, msg.tick);
  for (size_t i = 0; i < 3; ++i) PutDouble(out, 24 + 8 * i, msg.force[i]);
}

bool DecodeUdpPosition(const uint8_t* data, size_t size, UdpPosition* out) {
  // Version 2 is version 1 with the orientation after it.
  const bool oriented = size == kUdpOrientedBytes && Get<uint32_t>(data, 0) == kUdpPositionMagic &&
                        Get<uint16_t>(data, 4) == kUdpOrientedVersion;
  if (!oriented && !CheckHeader(data, size, kUdpPositionMagic)) return false;
  UdpPosition msg;
  if (oriented) {
    double norm = 0;
    for (size_t i = 0; i < 4; ++i) {
      msg.orientation[i] = GetDouble(data, 48 + 8 * i);
      norm += msg.orientation[i] * msg.orientation[i];
    }
    if (!std::isfinite(norm) || norm < 1e-12) return false;
    msg.oriented = true;
  }
  msg.flags = Get<uint16_t>(data, 6);
  msg.sequence = Get<uint32_t>(data, 8);
  msg.driver_time_ns = Get<uint64_t>(data, 16);
  for (size_t i = 0; i < 3; ++i) {
    msg.pos[i] = GetDouble(data, 24 + 8 * i);
    if (!std::isfinite(msg.pos[i])) return false;
  }
  *out = msg;
  return true;
}

bool DecodeUdpForce(const uint8_t* data, size_t size, UdpForce* out) {
  if (!CheckHeader(data, size, kUdpForceMagic)) return false;
  UdpForce msg;
  msg.flags = Get<uint16_t>(data, 6);
  msg.sequence = Get<uint32_t>(data, 8);
  msg.echo_sequence = Get<uint32_t>(data, 12);
  msg.tick = Get<uint64_t>(data, 16);
  for (size_t i = 0; i < 3; ++i) {
    msg.force[i] = GetDouble(data, 24 + 8 * i);
    if (!std::isfinite(msg.force[i])) return false;
  }
  *out = msg;
  return true;
}

}  // namespace idms::agent
