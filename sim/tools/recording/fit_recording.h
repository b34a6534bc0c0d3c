// idms-sim fit --recording: a session recording (the server's MCAP) as the fitter's trace, with the
// step and the tool its scene ran. Tool-side; built into idms-sim where the protocol and the
// agent's library are (device-agent/CMakeLists.txt adds it), since it maps the scene exactly as
// the agent that made the recording did (agent::SceneToLoop).
#pragma once

#include <string>

#include "fit.h"
#include "idms/sim/model.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"

namespace idms::tool {

// Reads the /device channel's tool positions and device forces (model frame, what the device was
// told) into *trace, tick by tick from the session's first, and the scene's step and tool from the
// recording's "idms.session" metadata. Refuses, with *error naming the file and the reason: a file
// that is not a session recording, a recording whose first mesh keyframe is not `model`'s surface
// (another vertex count, or a vertex more than 0.01 model units from its rest position), a tool
// that is not a sphere, missing ticks, a reset, a start after the session's first tick, and ticks
// where the passivity controller added damping (a force the tissue did not make).
bool ReadRecordingTrace(const std::string& path, const Model& model, fit::Trace* trace, StepOptions* step,
                        ToolCommand* tool, std::string* error);

}  // namespace idms::tool
