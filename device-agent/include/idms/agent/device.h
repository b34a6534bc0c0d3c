// Device backends for the agent's loop (--device SPEC): scripted interactions, a simulated hand,
// and the UDP bridge to a driver process. A device lives in device coordinates; the loop maps
// them to the model with the Registration.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "idms/agent/registration.h"
#include "idms/sim/state.h"

namespace idms {
struct Model;
}

namespace idms::agent {

// What the device says at the start of a tick.
struct DeviceReading {
  double pos[3] = {0, 0, 0};  // device frame, device units
  // The stylus's orientation, device frame, a unit quaternion (w, x, y, z), when `oriented`: a
  // needle's axis is its local -z. A device without one leaves the tool along the model's -z.
  double orientation[4] = {1, 0, 0, 0};
  bool oriented = false;
  bool closed = false;  // button held / tweezers closed
  // The scene tool the device holds from this tick (its index in Scene.tools); -1: the one it held.
  int32_t tool = -1;
  bool valid = false;  // false: no usable position this tick (not yet connected, timed out)
};

// Counters a device keeps (read after the loop stopped, or racily for display).
struct DeviceStats {
  uint64_t received = 0;  // udp: valid position datagrams
  uint64_t invalid = 0;   // udp: wrong size, magic, version or non-finite values
  uint64_t stale = 0;     // udp: not newer than one already used (reordered, duplicated)
  uint64_t lost = 0;      // udp: sequence numbers skipped
  uint64_t timeouts = 0;  // udp: ticks without a fresh position past the timeout
  uint64_t sent = 0;      // udp: force datagrams sent
};

// Read, Write and Release run on the loop thread and must not allocate, lock or log.
class Device {
 public:
  virtual ~Device() = default;
  // The input for tick `tick` at simulation time t_s (start of the tick).
  virtual void Read(int64_t tick, double t_s, DeviceReading* out) = 0;
  // The force for the device, device frame and units: finite and clamped (SanitizeDeviceForce).
  virtual void Write(int64_t tick, const double force[3]) = 0;
  // After the last tick: command zero force and let go.
  virtual void Release() = 0;
  virtual DeviceStats stats() const { return {}; }
  // True when the device has nothing more to give (a replay reached its end): the loop stops.
  virtual bool finished() const { return false; }
  // "scripted:palpate", ... for logs.
  virtual const char* name() const = 0;
};

// What building a device needs besides its spec.
struct DeviceContext {
  const Model* model = nullptr;  // scripted and human devices place their trajectory on its surface
  Registration registration;     // scripted trajectories are made in the model frame and mapped back
  double mio_radius = 1.5;       // model units: where contact starts, for the scripts
  double dt_s = 1e-3;            // loop period, s: the hand's integration step, the udp timeout's unit
  double mu_s = 0;               // the tool's static friction: the drag pushes at a fraction of mu_s f_n
  // The scene's tools' kinds, in its order: a script that changes tool (the suture's scalpel, then
  // needle) picks the first of the kind it asks for.
  ToolKind tool_kinds[kMaxTools] = {ToolKind::kSphere};
  int32_t num_tools = 1;
};

// Parses a --device spec and opens the device (the UDP socket is bound here):
//   scripted:palpate|stroke-slow|stroke-fast|pluck|stroke-gentle
//   scripted:drag[,fraction=F,depth=D,mass=M,damping=B,push=S]   press, then push sideways at
//                                           F mu_s f_n through a simulated hand (needs mu_s > 0)
//   human:SCRIPT[,mass=M][,k=K][,zeta=Z]   simulated hand (defaults 0.05, 60, 0.7)
//   udp:PORT[,bind=ADDR][,timeout_ms=T]     bridge (defaults 127.0.0.1, 50)
//   replay:FILE.mcap                        the /device channel of a session recording
// Returns null and an actionable message on a bad spec. Allocates; any thread.
std::unique_ptr<Device> MakeDevice(std::string_view spec, const DeviceContext& context, std::string* error);

// The script a scripted or human spec names ("pluck" for "human:pluck,k=80"), for scene defaults.
// False when the spec is of another kind.
bool DeviceScriptName(std::string_view spec, std::string* script);

}  // namespace idms::agent
