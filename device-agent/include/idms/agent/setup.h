// From a scene (idms.v1.Scene) to what the loop runs: step options, the tool, the registration.
// The boundary where scene values become sim types; everything here was validated by LoadScene.
#pragma once

#include <array>
#include <string>

#include "idms/agent/registration.h"
#include "idms/protocol/idms.pb.h"
#include "idms/sim/passivity.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"

namespace idms::agent {

// The scene used when --scene is not given: the thesis's tool for the named script (sphere MIO
// r 1.5, k 400, the thesis's contact law at 1 ms; tweezers for pluck) stepped with `preset`'s
// integrator and haptic window (default: symplectic Euler, r_l = 3; thesis: explicit Euler,
// r_l = 2.25), with defaults applied.
v1::Scene DefaultScene(const std::string& script, v1::Preset preset = v1::PRESET_DEFAULT);

// --friction mu_s=S[,mu_d=D,k_t=K,b_t=B] (idms-sim run's --tool items): replaces every tool's
// friction fields in the scene (so the recorded scene says what ran), validates it and fills the
// defaults again. False with a message naming the item or the field.
bool ApplyFrictionSpec(const std::string& spec, v1::Scene* scene, std::string* error);

// The passivity controller (DeviceMapping.passivity, docs/passivity.md): --passivity
// on|off[,window=S,max_damping=B,quantum=Q] (empty: the scene's) written into the scene, then an
// unset `enabled` decided by the device: on for udp: (a real hand on a real device: nothing else
// damps a buzz), off for the simulated and scripted devices and in PRESET_THESIS (the thesis's loop
// as it ran). The recorded scene says what ran. False with a message naming the item or field.
bool ApplyPassivitySpec(const std::string& spec, const std::string& device_spec, v1::Scene* scene, std::string* error);

// The scene's passivity options in the model frame and units the loop works in (lengths times
// the registration's scale, forces divided by its force_scale), for a loop period of dt_s.
PassivityOptions PassivityFromScene(const v1::Scene& scene, const Registration& registration, double dt_s);

// Maps a validated scene with defaults applied. Tool 0 is the one the device holds first (and
// whose local_radius the step takes); the scene may name up to kMaxTools, of which the device
// holds one at a time (SceneTools). False with a message naming the field.
bool SceneToLoop(const v1::Scene& scene, StepOptions* step, ToolCommand* tool, Registration* registration,
                 std::string* error);

// Every tool of a validated scene, in its order (LoopOptions::tools): the one device holds one at
// a time, and a script may change it (scripted:suture: the scalpel, then the needle).
bool SceneTools(const v1::Scene& scene, std::array<ToolCommand, kMaxTools>* tools, int32_t* num_tools,
                std::string* error);

}  // namespace idms::agent
