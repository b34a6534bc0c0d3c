// The scripted interactions of thesis chapter 6 — palpation (6.1.1), slow and fast stroking
// (6.1.2) at the thesis's speeds and plucking (6.1.3) — as reproducible MIO trajectories over any
// model's surface; a gentle stroke slow enough to watch; and a scan, shallow palpations over a
// grid for the fitter's stiffness map (thesis 7.2.5, issue 34); a needle's pierce, tilted, through
// the surface and back, and a stitch: a needle drawn down through the tissue, its thread left in,
// and tied (issue 32).
// Used by `idms-sim run`, the benches and the agent's scripted device.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

#include "idms/sim/tool.h"

namespace idms {

struct Model;

enum class Script : uint8_t { kPalpate, kStrokeSlow, kStrokeFast, kPluck, kStrokeGentle, kScan, kPierce, kStitch };

// The scan's grid: N x N points over the middle 60% of the surface in x and y, N from
// kMinScanGrid to kMaxScanGrid (ScriptGeometry::scan_grid; kScanGrid by default).
inline constexpr int kScanGrid = 7;
inline constexpr int kMinScanGrid = 2, kMaxScanGrid = 15;

// Where a script acts: the model's surface seen from above. For the hex fragment the top lies
// at z = 0 and the tool comes down along z (thesis figure 6-1).
struct ScriptGeometry {
  double center[2] = {0, 0};    // x, y of the palpation point (middle of the surface)
  double x_min = 0, x_max = 0;  // stroke extent along x
  double stroke_y = 0;          // stroke line (thesis: y = 1.5 on the fragment)
  double top_z = 0;             // highest external atom near the centre
  double mio_radius = 1.5;      // the MIO radius r: contact starts when z = top_z + r
  double y_min = 0, y_max = 0;  // the scan's extent along y (x: x_min..x_max)
  // The scan: its grid's points per side, and where the MIO first touches at each point, less its
  // radius (as top_z), row-major with x fastest.
  int scan_grid = kScanGrid;
  double scan_top_z[kMaxScanGrid * kMaxScanGrid] = {};
};

// One sample of the trajectory: the MIO centre (a needle's tip) in model units, the tweezers'
// state (a needle's tie command: the device's button), and the tool's orientation where the script gives one (the
// pierce: a unit quaternion w, x, y, z whose local -z is the needle's axis, tail to tip).
struct ScriptSample {
  double pos[3] = {0, 0, 0};
  bool closed = false;
  bool oriented = false;
  double orientation[4] = {1, 0, 0, 0};
};

// The pierce: the needle tilted this far from the vertical, in the x-z plane (its tip leads in +x),
// goes along its axis from kPierceHover before first contact to kPiercePast past it and back.
inline constexpr double kPierceTiltDeg = 30;
inline constexpr double kPierceHover = 1.0;
inline constexpr double kPiercePast = 2.0;
// The needle the pierce is made for: a 0.25 tip and springs for a tissue of element k about 15
// (the hex fragment's; docs/needle.md). The agent's scene for the script says the same.
ToolCommand PierceNeedle();

// The stitch: the pierce's needle upright over the middle atom, from kPierceHover above first
// contact straight down at kStitchSpeed until its tail is kStitchPast below where its tip first
// touched (a slab thinner than kStitchPast - the needle's length is passed through), held, then
// tied (the button pressed from kStitchTie s) and held until kStitchEnd s.
inline constexpr double kStitchSpeed = 1.0;  // model units / s
inline constexpr double kStitchPast = 3.0;   // model units
inline constexpr double kStitchTie = 10.5;   // s
inline constexpr double kStitchEnd = 14.0;   // s
// Its needle: PierceNeedle's, drawing a thread (SutureParams) of 8 units in 64 segments.
ToolCommand StitchNeedle();

// The script's geometry over `model`'s external atoms for an MIO of radius `mio_radius`, the scan
// on a scan_grid x scan_grid grid (clamped to [kMinScanGrid, kMaxScanGrid]).
ScriptGeometry MakeScriptGeometry(const Model& model, double mio_radius, int scan_grid = kScanGrid);

// The MIO pose at time t_s (clamped to [0, duration]). Smooth (C1) in position; pure function.
ScriptSample SampleScript(Script script, const ScriptGeometry& geometry, double t_s);

// The strokes' crossings of the surface while pressed in: [start, end] times in seconds, in order
// (one for stroke-slow and stroke-gentle, three for stroke-fast); empty for the other scripts.
std::vector<std::array<double, 2>> StrokeCrossings(Script script);

// Length of the script in seconds (the scan's on the default grid; on another, the overload).
double ScriptDuration(Script script);
double ScriptDuration(Script script, const ScriptGeometry& geometry);

// The scan's grid point i (0 .. scan_grid^2 - 1, x fastest): its x, y.
std::array<double, 2> ScanPoint(const ScriptGeometry& geometry, int i);

// "palpate", "stroke-slow", "stroke-fast", "pluck", "stroke-gentle", "scan", "pierce", "stitch".
const char* ScriptName(Script script);
bool ParseScriptName(std::string_view name, Script* script);

}  // namespace idms
