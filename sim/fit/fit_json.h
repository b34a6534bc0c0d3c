// A stiffness map as JSON: what `idms-sim fit --map --json` prints and what the server's fit jobs
// store in a mapped version's metadata (fit_jobs.cc), one shape for both.
#pragma once

#include <nlohmann/json.hpp>

#include "fit.h"

namespace idms::fit {

// {"presses", "background", "spread", "replays", "seconds", "lump": {"found"[, "x", "y", "xy_sigma",
// "radius", "ratio", "ratio_sigma", "presses"]}, "points": [{"x", "y", "scale", "sigma", "peak_force"}]}
nlohmann::json MapJson(const MapResult& r);

}  // namespace idms::fit
