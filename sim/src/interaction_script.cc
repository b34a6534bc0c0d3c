// Keyframed MIO trajectories for the thesis's interactions, eased with half-cosines so the
// velocity is continuous and zero at every keyframe.
#include "idms/sim/interaction_script.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include "idms/sim/model.h"

namespace idms {
namespace {

// How far the MIO centre goes below first contact (z = top + r), model units. The thesis gives
// forces, not depths: these were chosen so the hex fragment with k = 15, b = 0.2, m = 0.002 and
// a thesis-law MIO (k = 400, r = 1.5) peaks near its figures (palpation f_z ~ 1.7 N,
// slow stroke f_z ~ 1.3 N); docs/thesis-comparison.md shows the result.
constexpr double kPalpateDepth = 0.063;
constexpr double kStrokeDepth = 0.11;
constexpr double kPluckDepth = 0.02;
constexpr double kHover = 1.0;  // start and end this far above first contact
constexpr double kLift = 0.06;  // pluck: lift this far above first contact while holding

struct Key {
  double t;     // s
  double x;     // strokes: fraction of the way from x_min to x_max
  int stroke;   // 1: on the stroke line (x from the fraction); 0: above the palpation point
  double z;     // offset from first contact, model units (negative = pressed in)
  bool closed;  // tweezers closed from this key on
};

// Keyframes per script.
constexpr Key kPalpate[] = {{0.0, 0.5, 0, kHover, false},         {0.5, 0.5, 0, kHover, false},
                            {2.5, 0.5, 0, -kPalpateDepth, false}, {3.0, 0.5, 0, -kPalpateDepth, false},
                            {5.0, 0.5, 0, kHover, false},         {5.5, 0.5, 0, kHover, false}};
// The strokes at the thesis's speeds (docs/thesis-comparison.md, "Stroke speeds", says how they
// were derived: the seed has the figures' captions and text, not their plots, so the speeds are
// the ones at which this model gives the forces the text reports): the MIO comes down between
// t = 1 and 3 s as in fig. 6-5, then crosses the 2.4-unit stroke line once in 0.3 s (slow: the
// inertial part of f_x is -0.1 N while accelerating) or three times in 0.1 s each (fast: |f_x|
// reaches ~2 N each traversal), holds, and lifts off.
constexpr Key kStrokeSlow[] = {{0.0, 0.0, 1, kHover, false},        {1.0, 0.0, 1, kHover, false},
                               {3.0, 0.0, 1, -kStrokeDepth, false}, {3.3, 1.0, 1, -kStrokeDepth, false},
                               {4.3, 1.0, 1, -kStrokeDepth, false}, {5.8, 1.0, 1, kHover, false}};
constexpr Key kStrokeFast[] = {{0.0, 0.0, 1, kHover, false},        {1.0, 0.0, 1, kHover, false},
                               {3.0, 0.0, 1, -kStrokeDepth, false}, {3.1, 1.0, 1, -kStrokeDepth, false},
                               {3.2, 0.0, 1, -kStrokeDepth, false}, {3.3, 1.0, 1, -kStrokeDepth, false},
                               {4.3, 1.0, 1, -kStrokeDepth, false}, {5.8, 1.0, 1, kHover, false}};
// A gentle stroke, 13 times slower than the thesis's slow one (one crossing in 4 s): what a
// watcher can follow (the demo's live session) and the error-against-run-time bench's stroke
// (docs/error-vs-runtime.md was measured with it).
constexpr Key kStrokeGentle[] = {{0.0, 0.0, 1, kHover, false},        {1.0, 0.0, 1, kHover, false},
                                 {3.0, 0.0, 1, -kStrokeDepth, false}, {7.0, 1.0, 1, -kStrokeDepth, false},
                                 {8.0, 1.0, 1, -kStrokeDepth, false}, {9.5, 1.0, 1, kHover, false}};
constexpr Key kPluck[] = {{0.0, 0.5, 0, kHover, false}, {0.5, 0.5, 0, kHover, false}, {2.0, 0.5, 0, -kPluckDepth, true},
                          {3.5, 0.5, 0, kLift, true},   {4.0, 0.5, 0, kLift, false},  {5.0, 0.5, 0, kLift, false}};

// The scan (issue 34): at each grid point the MIO comes down from kScanHover above first contact
// (ContactUnder) to kScanDepth below it, holds, goes back up and moves to the next point, row by row in a
// serpentine. The depth is the palpation's order (0.063) but shallower: the tissue must stay
// elastic (non-destructive, thesis 7.2.5), and a lump is felt as the force at a depth, not by
// pressing harder.
constexpr double kScanDepth = 0.05;
constexpr double kScanHover = 0.3;
constexpr double kScanLead = 0.5;  // hover above the first point at the start, and the last at the end
constexpr double kScanDown = 0.3, kScanHold = 0.1, kScanUp = 0.3, kScanMove = 0.3;
constexpr double kScanPeriod = kScanDown + kScanHold + kScanUp + kScanMove;
// About 50 s for the 7 x 7 grid, 2 min for 11 x 11.
double ScanDuration(int grid) { return 2 * kScanLead + grid * grid * kScanPeriod - kScanMove; }

double Ease(double u) { return 0.5 * (1 - std::cos(std::numbers::pi * std::clamp(u, 0.0, 1.0))); }

// The grid index of the k-th point visited: rows in order, every other row backwards.
int ScanVisit(int k, int grid) {
  const int row = k / grid, col = k % grid;
  return row * grid + (row % 2 == 0 ? col : grid - 1 - col);
}

ScriptSample SampleScan(const ScriptGeometry& g, double t) {
  const int points = g.scan_grid * g.scan_grid;
  t = std::clamp(t, 0.0, ScanDuration(g.scan_grid));
  const double u = t - kScanLead;
  const int k = u < 0 ? 0 : std::min(static_cast<int>(u / kScanPeriod), points - 1);
  const double local = u - k * kScanPeriod;
  const int at = ScanVisit(k, g.scan_grid);
  const std::array<double, 2> p = ScanPoint(g, at);
  ScriptSample out;
  out.pos[0] = p[0], out.pos[1] = p[1];
  double base = g.scan_top_z[at] + g.mio_radius;
  double dz = kScanHover;
  if (local >= 0 && local < kScanDown) {
    dz = kScanHover - Ease(local / kScanDown) * (kScanHover + kScanDepth);
  } else if (local >= kScanDown && local < kScanDown + kScanHold) {
    dz = -kScanDepth;
  } else if (local >= kScanDown + kScanHold && local < kScanDown + kScanHold + kScanUp) {
    dz = -kScanDepth + Ease((local - kScanDown - kScanHold) / kScanUp) * (kScanHover + kScanDepth);
  } else if (local >= kScanPeriod - kScanMove && k + 1 < points) {
    const int next = ScanVisit(k + 1, g.scan_grid);
    const std::array<double, 2> q = ScanPoint(g, next);
    const double s = Ease((local - (kScanPeriod - kScanMove)) / kScanMove);
    out.pos[0] = p[0] + s * (q[0] - p[0]), out.pos[1] = p[1] + s * (q[1] - p[1]);
    base += s * (g.scan_top_z[next] - g.scan_top_z[at]);
  }
  out.pos[2] = base + dz;
  return out;
}

template <size_t N>
ScriptSample Interpolate(const Key (&keys)[N], const ScriptGeometry& g, double t) {
  t = std::clamp(t, 0.0, keys[N - 1].t);
  size_t i = 0;
  while (i + 2 < N && t >= keys[i + 1].t) ++i;
  const Key& a = keys[i];
  const Key& b = keys[i + 1];
  const double u = std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0);
  const double s = 0.5 * (1 - std::cos(std::numbers::pi * u));  // half-cosine ease
  const double fx = a.x + s * (b.x - a.x);
  ScriptSample out;
  out.pos[0] = a.stroke ? g.x_min + fx * (g.x_max - g.x_min) : g.center[0];
  out.pos[1] = a.stroke ? g.stroke_y : g.center[1];
  out.pos[2] = g.top_z + g.mio_radius + a.z + s * (b.z - a.z);
  // The tweezers close when the key that starts closed is reached, and open at the first open key.
  out.closed = t >= b.t ? b.closed : a.closed;
  return out;
}

template <size_t N>
std::vector<std::array<double, 2>> Crossings(const Key (&keys)[N]) {
  std::vector<std::array<double, 2>> out;
  for (size_t i = 0; i + 1 < N; ++i) {
    if (keys[i].stroke && keys[i].x != keys[i + 1].x) out.push_back({keys[i].t, keys[i + 1].t});
  }
  return out;
}

// The highest external atom within `radius` of the vertical line through xy; `otherwise` if none.
double TopUnder(const Model& model, std::array<double, 2> xy, double radius, double otherwise) {
  double top = -std::numeric_limits<double>::infinity();
  for (int32_t atom : model.external_atoms) {
    const double* p = &model.atom_pos_eq[3 * atom];
    if (std::hypot(p[0] - xy[0], p[1] - xy[1]) <= radius) top = std::max(top, p[2]);
  }
  return std::isfinite(top) ? top : otherwise;
}

// Where a sphere of `radius` coming down the vertical line through xy first touches an external
// atom: its centre's height there minus the radius (`otherwise` if it touches none). A grid point
// need not lie above an atom: between atoms the sphere sinks further before it touches, and a
// press to a depth below top + r could miss the surface altogether.
double ContactUnder(const Model& model, std::array<double, 2> xy, double radius, double otherwise) {
  double top = -std::numeric_limits<double>::infinity();
  for (int32_t atom : model.external_atoms) {
    const double* p = &model.atom_pos_eq[3 * atom];
    const double d = std::hypot(p[0] - xy[0], p[1] - xy[1]);
    if (d < radius) top = std::max(top, p[2] + std::sqrt(radius * radius - d * d) - radius);
  }
  return std::isfinite(top) ? top : otherwise;
}

// The pierce: the tip's distance past first contact along the needle's axis (negative: short of
// it) at each key; about 0.5 units/s in and out (0.8 at the ease's fastest).
struct PierceKey {
  double t;  // s
  double s;  // model units along the axis
};
constexpr PierceKey kPierce[] = {{0.0, -kPierceHover}, {0.5, -kPierceHover},  {6.5, kPiercePast},
                                 {7.5, kPiercePast},   {13.5, -kPierceHover}, {14.0, -kPierceHover}};

ScriptSample SamplePierce(const ScriptGeometry& g, double t) {
  t = std::clamp(t, 0.0, std::end(kPierce)[-1].t);
  size_t i = 0;
  while (i + 2 < std::size(kPierce) && t >= kPierce[i + 1].t) ++i;
  const PierceKey& a = kPierce[i];
  const PierceKey& b = kPierce[i + 1];
  const double s = a.s + Ease((t - a.t) / (b.t - a.t)) * (b.s - a.s);
  // A turn of -tilt about y takes the local -z to (sin tilt, 0, -cos tilt).
  const double tilt = kPierceTiltDeg * std::numbers::pi / 180;
  const double axis[3] = {std::sin(tilt), 0, -std::cos(tilt)};
  // The tip's centre touches the atom under the centre (g.center, g.top_z) at s = 0.
  ScriptSample out;
  const double p[3] = {g.center[0], g.center[1], g.top_z};
  for (int c = 0; c < 3; ++c) out.pos[c] = p[c] + (s - g.mio_radius) * axis[c];
  out.oriented = true;
  out.orientation[0] = std::cos(tilt / 2), out.orientation[2] = -std::sin(tilt / 2);
  return out;
}

ScriptSample SampleStitch(const ScriptGeometry& g, double t) {
  t = std::clamp(t, 0.0, kStitchEnd);
  const double length = StitchNeedle().needle.length;
  // The tip's distance below first contact: -hover, held 0.5 s, then down at the stitch's speed.
  const double travel = kPierceHover + length + kStitchPast;
  const double s = -kPierceHover + std::min(travel, kStitchSpeed * std::max(0.0, t - 0.5));
  ScriptSample out;
  out.pos[0] = g.center[0], out.pos[1] = g.center[1], out.pos[2] = g.top_z + g.mio_radius - s;
  out.oriented = true;  // upright: the identity, the needle's axis -z
  out.closed = t >= kStitchTie;
  return out;
}

// The suture: keys of the tool's pose, eased from each to the next with half-cosines. For the
// needle, p is the needle's midpoint and theta its turn about x (0: upright, the axis -z; pi:
// the axis +z), so a turn swings it about its middle and a move with theta held slides it along
// its own axis; for the scalpel, p is the blade's base. Between keys of different tools the first
// is held; the button is the first key's.
struct SutureKey {
  double t = 0;
  ToolKind kind = ToolKind::kNeedle;
  double p[3] = {0, 0, 0};
  double theta = 0;
  bool button = false;
};
constexpr int kMaxSutureKeys = 6 + 12 * kSutureStitches;  // the incision's 5, 12 a stitch, the hold

// The needle's midpoint for its tip at `tip` with the turn theta.
void MidpointFor(const double tip[3], double theta, double half, double out[3]) {
  out[0] = tip[0], out[1] = tip[1] - half * std::sin(theta), out[2] = tip[2] + half * std::cos(theta);
}

int SutureKeys(const ScriptGeometry& g, SutureKey keys[kMaxSutureKeys]) {
  int n = 0;
  double t = 0;
  auto add = [&](double dt, ToolKind kind, const double p[3], double theta, bool button = false) {
    t += dt;
    SutureKey& k = keys[std::min(n++, kMaxSutureKeys - 1)];  // 5 + 12 x 3 + 1: exactly kMaxSutureKeys
    k.t = t, k.kind = kind, k.theta = theta, k.button = button;
    std::copy(p, p + 3, k.p);
  };
  // The incision: the blade plunged at the start, swept to the end, lifted.
  const double top = g.top_z;
  const double blade = kSutureBlade;  // IncisionScalpel's
  const double above[3] = {g.incision_x, g.incision_y[0], top + kSutureClear + blade};
  const double in[3] = {g.incision_x, g.incision_y[0], top + kSutureClear};
  const double end[3] = {g.incision_x, g.incision_y[1], top + kSutureClear};
  const double lifted[3] = {g.incision_x, g.incision_y[1], top + kSutureClear + blade};
  add(0, ToolKind::kScalpel, above, 0);
  add(0.5, ToolKind::kScalpel, above, 0);
  add(1.0, ToolKind::kScalpel, in, 0);
  add((g.incision_y[1] - g.incision_y[0]) / kIncisionSpeed, ToolKind::kScalpel, end, 0);
  add(1.0, ToolKind::kScalpel, lifted, 0);
  // The stitches.
  const double len = SutureScriptNeedle().needle.length, half = 0.5 * len, r = SutureScriptNeedle().radius;
  const double pi = std::numbers::pi;
  for (int k = 0; k < kSutureStitches; ++k) {
    const int row = std::max(g.stitch_rows[k], 0);
    const double* a = g.incision_rest[row][0];
    const double* b = g.incision_rest[row][1];
    double m[3];
    // Over A, upright, its tip kPierceHover above first contact (the first: where it appears).
    const double hover[3] = {a[0], a[1], a[2] + r + kPierceHover};
    MidpointFor(hover, 0, half, m);
    add(k == 0 ? 0.5 : 1.5, ToolKind::kNeedle, m, 0);
    add(0.5, ToolKind::kNeedle, m, 0);
    // Down through A until the tail is kSutureClear below the slab.
    const double below[3] = {a[0], a[1], g.bottom_z - kSutureClear - len};
    MidpointFor(below, 0, half, m);
    add((hover[2] - below[2]) / kStitchSpeed, ToolKind::kNeedle, m, 0);
    // Turned over beneath, then across under B.
    add(2.0, ToolKind::kNeedle, m, pi);
    const double under[3] = {b[0], b[1], g.bottom_z - kSutureClear};
    MidpointFor(under, pi, half, m);
    add(1.0, ToolKind::kNeedle, m, pi);
    // Up through B until the tail is kSutureClear above it; tied there, held.
    const double out[3] = {b[0], b[1], b[2] + kSutureClear + len};
    MidpointFor(out, pi, half, m);
    add((out[2] - under[2]) / kStitchSpeed, ToolKind::kNeedle, m, pi);
    // Drawn on through (the stitch snug against the knot before it, or the first leaving a short
    // tail) and back: what lies beyond this stitch's knot makes the next.
    const double pulled[3] = {m[0], m[1], m[2] + kSuturePull[k]};
    add(kSuturePull[k] / kSuturePullSpeed, ToolKind::kNeedle, pulled, pi);
    add(kSuturePull[k] / kSuturePullSpeed, ToolKind::kNeedle, m, pi);
    add(0.25, ToolKind::kNeedle, m, pi, true);
    add(1.75, ToolKind::kNeedle, m, pi);
    add(0.5, ToolKind::kNeedle, m, pi);
    // Turned back upright above (its tip swings back the way it came).
    add(2.0, ToolKind::kNeedle, m, 0);
  }
  // Held still: the stitches released.
  add(kSutureHold, ToolKind::kNeedle, keys[n - 1].p, 0);
  return n;
}

ScriptSample SampleSuture(const ScriptGeometry& g, double t) {
  SutureKey keys[kMaxSutureKeys];
  const int n = SutureKeys(g, keys);
  t = std::clamp(t, 0.0, keys[n - 1].t);
  int i = 0;
  while (i + 2 < n && t >= keys[i + 1].t) ++i;
  const SutureKey& a = keys[i];
  const SutureKey& b = keys[i + 1];
  const double s = a.kind == b.kind && b.t > a.t ? Ease((t - a.t) / (b.t - a.t)) : (t >= b.t ? 1.0 : 0.0);
  const SutureKey& held = a.kind == b.kind ? a : (t >= b.t ? b : a);
  ScriptSample out;
  out.kind = held.kind;
  out.closed = a.button && t < b.t;
  double p[3];
  for (int c = 0; c < 3; ++c) p[c] = a.kind == b.kind ? a.p[c] + s * (b.p[c] - a.p[c]) : held.p[c];
  if (out.kind == ToolKind::kScalpel) {
    std::copy(p, p + 3, out.pos);
    return out;
  }
  const double theta = a.kind == b.kind ? a.theta + s * (b.theta - a.theta) : held.theta;
  const double half = 0.5 * SutureScriptNeedle().needle.length;
  // The tip: the midpoint plus half the length along the axis (0, sin theta, -cos theta).
  out.pos[0] = p[0], out.pos[1] = p[1] + half * std::sin(theta), out.pos[2] = p[2] - half * std::cos(theta);
  out.oriented = true;
  out.orientation[0] = std::cos(theta / 2), out.orientation[1] = std::sin(theta / 2);
  return out;
}

double SutureDuration(const ScriptGeometry& g) {
  SutureKey keys[kMaxSutureKeys];
  return keys[SutureKeys(g, keys) - 1].t;
}

// The incision's rows and pairs, the stitches' rows, and the slab's bottom (ScriptGeometry).
void MakeIncision(const Model& model, ScriptGeometry& g) {
  const double cx = g.center[0], cy = g.center[1];
  double spacing = std::numeric_limits<double>::infinity(), pitch = spacing;
  for (int32_t atom : model.external_atoms) {
    const double* p = &model.atom_pos_eq[3 * atom];
    const double d = std::hypot(p[0] - cx, p[1] - cy);
    if (d > 1e-9) spacing = std::min(spacing, d);
  }
  if (!std::isfinite(spacing)) return;
  for (int32_t atom : model.external_atoms) {
    const double dy = model.atom_pos_eq[3 * atom + 1] - cy;
    if (dy > 0.25 * spacing) pitch = std::min(pitch, dy);
  }
  if (!std::isfinite(pitch)) pitch = spacing;
  g.incision_x = cx + 0.25 * spacing;
  g.bottom_z = g.top_z;
  for (int32_t i = 0; i < model.num_atoms; ++i) {
    const double* p = &model.atom_pos_eq[3 * i];
    if (!model.atom_fixed[i] && std::hypot(p[0] - cx, p[1] - cy) < 1.5 * spacing)
      g.bottom_z = std::min(g.bottom_z, p[2]);
  }
  // Three rows either side of the centre's: the facing pair in each.
  constexpr int kRowsEachSide = 3;
  static_assert(2 * kRowsEachSide + 1 <= kMaxIncisionRows);
  std::fill(g.stitch_rows, g.stitch_rows + kSutureStitches, -1);
  int first = kRowsEachSide + 1, last = -kRowsEachSide - 1;
  for (int j = -kRowsEachSide; j <= kRowsEachSide; ++j) {
    const double y = cy + j * pitch;
    int32_t pair[2] = {-1, -1};
    double best[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    for (int32_t atom : model.external_atoms) {
      const double* p = &model.atom_pos_eq[3 * atom];
      if (std::fabs(p[1] - y) > 0.25 * pitch) continue;
      const int side = p[0] < g.incision_x ? 0 : 1;
      const double d = std::fabs(p[0] - g.incision_x);
      if (d < best[side] && d < 1.5 * spacing) best[side] = d, pair[side] = atom;
    }
    if (pair[0] < 0 || pair[1] < 0) continue;
    const int row = g.num_incision_rows++;
    for (int side = 0; side < 2; ++side) {
      g.incision_pairs[row][side] = pair[side];
      std::copy_n(&model.atom_pos_eq[3 * pair[side]], 3, g.incision_rest[row][side]);
    }
    if (j >= -1 && j <= 1) g.stitch_rows[j + 1] = row;
    first = std::min(first, j), last = std::max(last, j);
  }
  if (g.num_incision_rows == 0) return;
  g.incision_y[0] = cy + (first - 0.5) * pitch;
  g.incision_y[1] = cy + (last + 0.5) * pitch;
}

}  // namespace

ToolCommand StitchNeedle() {
  ToolCommand c = PierceNeedle();
  c.suture.length = 8;
  c.suture.segments = 64;
  c.suture.mass = 0.01;
  return c;
}

ToolCommand IncisionScalpel() {
  ToolCommand c;
  c.kind = ToolKind::kScalpel;
  c.radius = 0.05;
  c.blade[2] = -kSutureBlade;
  return c;
}

ToolCommand SutureScriptNeedle() {
  ToolCommand c = PierceNeedle();
  c.needle.length = 3;
  c.needle.puncture_force = 0.3;
  c.needle.grip = 0.2;
  c.needle.capture_radius = 0.7;
  c.needle.lateral_stiffness = 3;
  c.needle.axial_stiffness = 30;
  c.suture.length = 24;
  c.suture.segments = 128;
  c.suture.mass = 0.02;
  c.suture.tie_force = 2;
  c.suture.hold_stiffness = 30;  // a hole holds its thread within a tie force / 30 = 0.07
  return c;
}

double IncisionGap(const ScriptGeometry& g, const Real* atom_pos, bool stitched_only) {
  int lo = 0, hi = g.num_incision_rows - 1;
  if (stitched_only) {
    lo = kMaxIncisionRows, hi = -1;
    for (int row : g.stitch_rows) {
      if (row >= 0) lo = std::min(lo, row), hi = std::max(hi, row);
    }
  }
  double sum = 0;
  int n = 0;
  for (int row = lo; row <= hi; ++row) {
    const Real* a = &atom_pos[3 * g.incision_pairs[row][0]];
    const Real* b = &atom_pos[3 * g.incision_pairs[row][1]];
    sum += std::hypot(static_cast<double>(b[0] - a[0]), static_cast<double>(b[1] - a[1]),
                      static_cast<double>(b[2] - a[2]));
    ++n;
  }
  return n > 0 ? sum / n : std::nan("");
}

ToolCommand PierceNeedle() {
  ToolCommand c;
  c.kind = ToolKind::kNeedle;
  c.radius = 0.25;
  c.stiffness = 400;
  c.law = ContactLaw::kLinear;
  c.needle.length = 5;
  c.needle.puncture_force = 1;
  c.needle.mu = 0.5;
  c.needle.grip = 1;
  c.needle.capture_radius = 0.7;
  c.needle.lateral_stiffness = 20;
  c.needle.axial_stiffness = 100;
  return c;
}

std::array<double, 2> ScanPoint(const ScriptGeometry& g, int i) {
  const int n = g.scan_grid;
  const double fx = static_cast<double>(i % n) / (n - 1);
  const double fy = static_cast<double>(i / n) / (n - 1);
  return {g.x_min + fx * (g.x_max - g.x_min), g.y_min + fy * (g.y_max - g.y_min)};
}

std::vector<std::array<double, 2>> StrokeCrossings(Script script) {
  switch (script) {
    case Script::kStrokeSlow:
      return Crossings(kStrokeSlow);
    case Script::kStrokeFast:
      return Crossings(kStrokeFast);
    case Script::kStrokeGentle:
      return Crossings(kStrokeGentle);
    case Script::kPalpate:
    case Script::kPluck:
    case Script::kScan:
    case Script::kPierce:
    case Script::kStitch:
    case Script::kSuture:
      break;
  }
  return {};
}

ScriptGeometry MakeScriptGeometry(const Model& model, double mio_radius, int scan_grid) {
  ScriptGeometry g;
  g.mio_radius = mio_radius;
  g.scan_grid = std::clamp(scan_grid, kMinScanGrid, kMaxScanGrid);
  double lo[3], hi[3];
  for (int c = 0; c < 3; ++c) lo[c] = std::numeric_limits<double>::infinity(), hi[c] = -lo[c];
  for (int32_t atom : model.external_atoms) {
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], model.atom_pos_eq[3 * atom + c]);
      hi[c] = std::max(hi[c], model.atom_pos_eq[3 * atom + c]);
    }
  }
  if (model.external_atoms.empty()) return g;
  // Palpate straight above the external atom nearest the middle, so contact starts at z = top + r
  // (thesis 6.1.1: "f_z becomes nonzero at approximately z = 1.5, which is the radius").
  const double mid[2] = {0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])};
  double best = std::numeric_limits<double>::infinity();
  for (int32_t atom : model.external_atoms) {
    const double* p = &model.atom_pos_eq[3 * atom];
    const double d = std::hypot(p[0] - mid[0], p[1] - mid[1]);
    if (d < best) best = d, g.center[0] = p[0], g.center[1] = p[1];
  }
  // Strokes cover the middle 60% in x; on the fragment (x 0..4) that is 0.8..3.2.
  g.x_min = lo[0] + 0.2 * (hi[0] - lo[0]);
  g.x_max = hi[0] - 0.2 * (hi[0] - lo[0]);
  // The thesis strokes at y = 1.5 on the 3.46-deep fragment.
  g.stroke_y = lo[1] + (1.5 / 3.464) * (hi[1] - lo[1]);
  g.y_min = lo[1] + 0.2 * (hi[1] - lo[1]);
  g.y_max = hi[1] - 0.2 * (hi[1] - lo[1]);
  // The surface under the tool: the highest external atom within one radius of the centre line.
  g.top_z = TopUnder(model, {g.center[0], g.center[1]}, mio_radius, hi[2]);
  for (int i = 0; i < g.scan_grid * g.scan_grid; ++i)
    g.scan_top_z[i] = ContactUnder(model, ScanPoint(g, i), mio_radius, hi[2]);
  MakeIncision(model, g);
  return g;
}

ScriptSample SampleScript(Script script, const ScriptGeometry& g, double t) {
  switch (script) {
    case Script::kPalpate:
      return Interpolate(kPalpate, g, t);
    case Script::kStrokeSlow:
      return Interpolate(kStrokeSlow, g, t);
    case Script::kStrokeFast:
      return Interpolate(kStrokeFast, g, t);
    case Script::kStrokeGentle:
      return Interpolate(kStrokeGentle, g, t);
    case Script::kPluck:
      return Interpolate(kPluck, g, t);
    case Script::kScan:
      return SampleScan(g, t);
    case Script::kPierce:
      return SamplePierce(g, t);
    case Script::kStitch:
      return SampleStitch(g, t);
    case Script::kSuture:
      return SampleSuture(g, t);
  }
  return {};
}

double ScriptDuration(Script script) {
  switch (script) {
    case Script::kPalpate:
      return std::end(kPalpate)[-1].t;
    case Script::kStrokeSlow:
      return std::end(kStrokeSlow)[-1].t;
    case Script::kStrokeFast:
      return std::end(kStrokeFast)[-1].t;
    case Script::kStrokeGentle:
      return std::end(kStrokeGentle)[-1].t;
    case Script::kPluck:
      return std::end(kPluck)[-1].t;
    case Script::kScan:
      return ScanDuration(kScanGrid);
    case Script::kPierce:
      return std::end(kPierce)[-1].t;
    case Script::kStitch:
      return kStitchEnd;
    case Script::kSuture:
      break;  // the geometry's: the overload
  }
  return 0;
}

double ScriptDuration(Script script, const ScriptGeometry& geometry) {
  if (script == Script::kSuture) return SutureDuration(geometry);
  return script == Script::kScan ? ScanDuration(geometry.scan_grid) : ScriptDuration(script);
}

const char* ScriptName(Script script) {
  switch (script) {
    case Script::kPalpate:
      return "palpate";
    case Script::kStrokeSlow:
      return "stroke-slow";
    case Script::kStrokeFast:
      return "stroke-fast";
    case Script::kStrokeGentle:
      return "stroke-gentle";
    case Script::kPluck:
      return "pluck";
    case Script::kScan:
      return "scan";
    case Script::kPierce:
      return "pierce";
    case Script::kStitch:
      return "stitch";
    case Script::kSuture:
      return "suture";
  }
  return "?";
}

bool ParseScriptName(std::string_view name, Script* script) {
  for (Script s : {Script::kPalpate, Script::kStrokeSlow, Script::kStrokeFast, Script::kPluck, Script::kStrokeGentle,
                   Script::kScan, Script::kPierce, Script::kStitch, Script::kSuture}) {
    if (name == ScriptName(s)) {
      *script = s;
      return true;
    }
  }
  return false;
}

}  // namespace idms
