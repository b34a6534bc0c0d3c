// The scripted interactions of thesis chapter 6 — palpation (6.1.1), slow and fast stroking
// (6.1.2) at the thesis's speeds and plucking (6.1.3) — as reproducible MIO trajectories over any
// model's surface; a gentle stroke slow enough to watch; and a scan, shallow palpations over a
// grid for the fitter's stiffness map (thesis 7.2.5, issue 34); a needle's pierce, tilted, through
// the surface and back, and a stitch: a needle drawn down through the tissue, its thread left in,
// and tied; and a suture: a slab incised with the scalpel, then three stitches placed across the
// incision and tied (issue 32).
// Used by `idms-sim run`, the benches and the agent's scripted device.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

#include "idms/sim/tool.h"

namespace idms {

struct Model;

enum class Script : uint8_t {
  kPalpate,
  kStrokeSlow,
  kStrokeFast,
  kPluck,
  kStrokeGentle,
  kScan,
  kPierce,
  kStitch,
  kSuture
};

// The scan's grid: N x N points over the middle 60% of the surface in x and y, N from
// kMinScanGrid to kMaxScanGrid (ScriptGeometry::scan_grid; kScanGrid by default).
inline constexpr int kScanGrid = 7;
inline constexpr int kMinScanGrid = 2, kMaxScanGrid = 15;

// The suture's stitches, and the most rows of top atoms its incision crosses.
inline constexpr int kSutureStitches = 3;
inline constexpr int kMaxIncisionRows = 16;

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
  // The suture: an incision along y at x = incision_x, a quarter of the top grid's spacing past the
  // centre atom (so that it runs between two columns of atoms in every row), from incision_y[0] to
  // incision_y[1] (three rows either side of the centre's), through the slab down to bottom_z (the
  // lowest free atom under the centre). Per row it crosses, the facing pair of top atoms: A, the
  // nearest left of the incision, and B, the nearest right (model atom ids), at rest. Its
  // kSutureStitches stitches go across the pairs of the centre row and the rows either side.
  double incision_x = 0, incision_y[2] = {0, 0}, bottom_z = 0;
  int num_incision_rows = 0;
  int32_t incision_pairs[kMaxIncisionRows][2] = {};
  double incision_rest[kMaxIncisionRows][2][3] = {};
  int stitch_rows[kSutureStitches] = {};  // indices into incision_pairs (-1: the model has no such row)
};

// One sample of the trajectory: the MIO centre (a needle's tip) in model units, the tweezers'
// state (a needle's tie command: the device's button), and the tool's orientation where the script gives one (the
// pierce: a unit quaternion w, x, y, z whose local -z is the needle's axis, tail to tip).
struct ScriptSample {
  ToolKind kind = ToolKind::kNone;  // the tool the script holds now (the suture's); kNone: the run's own
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

// The suture: the scalpel's blade through the slab from a start at y = incision_y[0] to its end,
// at kIncisionSpeed; then for each stitch the needle (upright) over A, down through the slab until
// its tail is kSutureClear below it, turned over beneath, across under B, up through the slab
// until its tail is kSutureClear above, drawn on kSuturePull[stitch] further at kSuturePullSpeed
// and back (the thread drawn through until the stitch is snug against the knot before it, the
// first leaving a short tail: the knot fixes the thread, so the next stitch is made with what lies
// beyond it), the button pressed to tie, turned back above and on to the
// next A; after the last, held still kSutureHold s (the stitches released: the goal's 5 s).
inline constexpr double kIncisionSpeed = 1.0;  // model units / s
inline constexpr double kSutureClear = 0.7;    // model units
inline constexpr double kSutureHold = 5.0;     // s
// The pulls for SutureScriptNeedle's 24-unit thread: each stitch takes about 3.6 units of it
// (through both sides, under the incision, and across from the knot before).
inline constexpr double kSuturePull[kSutureStitches] = {16.0, 12.0, 8.0};  // model units
inline constexpr double kSuturePullSpeed = 3.0;                            // model units / s
// Its haptic window's radius (model units): the tissue around every puncture moves as the wound
// is drawn together, not only the punctured atoms (the needle's tip radius would give 0.5).
inline constexpr double kSutureLocalRadius = 2.0;
// Its scalpel's blade, model units: from kSutureClear above the slab's top to well below a slab
// up to 1.5 units thick (the suture slab's is 0.816).
inline constexpr double kSutureBlade = 3.0;
// Its tools: a scalpel whose blade (kSutureBlade) reaches through the slab from above it, and a 3-unit
// needle for a soft tissue (element k about 1.5: models/suture_slab) drawing a 24-unit thread.
ToolCommand IncisionScalpel();
ToolCommand SutureScriptNeedle();
// The incision's gap: the mean distance between its facing pairs of top atoms, over the stitched
// rows (the stitches' first to last) or over every row it crosses. NaN without an incision.
double IncisionGap(const ScriptGeometry& geometry, const Real* atom_pos, bool stitched_only);

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

// "palpate", "stroke-slow", "stroke-fast", "pluck", "stroke-gentle", "scan", "pierce", "stitch",
// "suture".
const char* ScriptName(Script script);
bool ParseScriptName(std::string_view name, Script* script);

}  // namespace idms
