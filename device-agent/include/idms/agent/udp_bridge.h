// The UDP device bridge (protocol/udp_bridge.md): fixed-size little-endian datagrams, position
// in from a driver process, force out to it. Encoders and decoders shared by the agent's udp:
// device and by drivers (the tests' fake driver). Pure functions; no allocation.
#pragma once

#include <cstddef>
#include <cstdint>

namespace idms::agent {

inline constexpr uint32_t kUdpPositionMagic = 0x504D4449;  // bytes 'I' 'D' 'M' 'P'
inline constexpr uint32_t kUdpForceMagic = 0x464D4449;     // bytes 'I' 'D' 'M' 'F'
inline constexpr uint16_t kUdpBridgeVersion = 1;
inline constexpr size_t kUdpDatagramBytes = 48;  // both directions, version 1
// A position with the stylus's orientation: version 2, 80 bytes (version 1's 48, then w, x, y, z).
inline constexpr uint16_t kUdpOrientedVersion = 2;
inline constexpr size_t kUdpOrientedBytes = 80;
inline constexpr size_t kUdpMaxDatagramBytes = kUdpOrientedBytes;

// Position datagram flags.
inline constexpr uint16_t kUdpButton = 1;  // the device's button is held (tweezers closed)

// Force datagram flags.
inline constexpr uint16_t kUdpForceActive = 1;    // the force comes from the simulation
inline constexpr uint16_t kUdpForceTimeout = 2;   // no fresh position within the timeout: force is zero
inline constexpr uint16_t kUdpForceShutdown = 4;  // the agent is stopping: force is zero, no more follow

// Driver -> agent, once per device servo tick.
struct UdpPosition {
  uint16_t flags = 0;
  uint32_t sequence = 0;        // +1 per datagram, wraps; the agent uses only the newest
  uint64_t driver_time_ns = 0;  // the driver's clock, echoed in logs only
  double pos[3] = {0, 0, 0};    // device frame, device units
  // Version 2: the stylus's orientation, device frame, a quaternion (w, x, y, z) that is finite and
  // nonzero (the agent normalises it); a needle's axis is its local -z.
  bool oriented = false;
  double orientation[4] = {1, 0, 0, 0};
};

// Agent -> driver, once per loop tick once a position has arrived.
struct UdpForce {
  uint16_t flags = 0;
  uint32_t sequence = 0;        // +1 per datagram, wraps
  uint32_t echo_sequence = 0;   // the sequence of the position this force answers
  uint64_t tick = 0;            // the agent's loop tick
  double force[3] = {0, 0, 0};  // device frame, device force units, finite, clamped
};

// A position: version 1 (kUdpDatagramBytes) without an orientation, 2 (kUdpOrientedBytes) with
// one; returns the bytes written. A force: exactly kUdpDatagramBytes.
size_t EncodeUdpPosition(const UdpPosition& msg, uint8_t out[kUdpMaxDatagramBytes]);
void EncodeUdpForce(const UdpForce& msg, uint8_t out[kUdpDatagramBytes]);
// False on a wrong size for its version, a wrong magic or version, a non-finite value, or a zero
// orientation.
bool DecodeUdpPosition(const uint8_t* data, size_t size, UdpPosition* out);
bool DecodeUdpForce(const uint8_t* data, size_t size, UdpForce* out);

// Serial-number order on 32-bit sequences (RFC 1982): a is newer than b.
inline bool UdpSequenceNewer(uint32_t a, uint32_t b) { return static_cast<int32_t>(a - b) > 0; }

}  // namespace idms::agent
