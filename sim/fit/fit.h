// Fitting a model to what was felt (thesis 7.2.5, issue 34): given a recorded tool path and the
// force measured along it, the element parameters that make the simulated force match. The path
// is replayed through the real Step, and Ceres Solver minimises the force error over scale
// factors of the home elements' and the surface elements' stiffness and damping.
//
// Why scale factors: a model's elements need not be uniform (a tumour's are stiffer), and one
// factor per group keeps their ratios while fitting the level; on a uniform group the factor times
// the typed-in value is the fitted value itself. The factors are solved in log space (positive by
// construction, and a factor of 2 is as far from 1 as a factor of 1/2).
#pragma once

#include <array>
#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "idms/sim/interaction_script.h"
#include "idms/sim/model.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"

namespace idms::fit {

// A recorded interaction: per tick, the tool's position (model frame) and the device force it
// produced, at a fixed tick dt_s. Row n is the state after tick n + 1, as `idms-sim run --csv`
// writes it.
struct Trace {
  double dt_s = 1e-3;
  std::vector<std::array<double, 3>> pos;
  std::vector<std::array<double, 3>> force;
  // The tweezers closed at each tick (1), as many as pos; empty: never (a sphere's recording).
  std::vector<uint8_t> closed;
};

// Reads the columns t,x,y,z,fx,fy,fz of an `idms-sim run --csv` file, and `closed` where it has
// one (a tweezers' run: 0 or 1); the others are ignored.
// The tick is taken from t (uniform within 1e-6 s, or it is refused). False with *error naming the
// file and line.
bool ReadTraceCsv(const std::string& path, Trace* trace, std::string* error);

// The element groups' stiffness and damping, every element's, and the MIO's contact stiffness
// (the tool's k, which the recording's tool command gives; its factor scales the tool, not the
// model).
enum class Param : uint8_t { kHomeK, kHomeB, kSurfaceK, kSurfaceB, kToolK, kK, kB };
inline constexpr int kNumParams = 7;
const char* ParamName(Param p);  // "home_k", "home_b", "surface_k", "surface_b", "tool_k", "k", "b"

// "home_k,surface_k" -> params (each once; k and b overlap the groups' and are refused beside
// them). False with *error naming the bad item.
bool ParseParams(const std::string& list, std::vector<Param>* params, std::string* error);

// The group's mean typed-in value in `model` (home or surface elements', or every element's, k or
// b); 0 if the group is empty, and for tool_k (not the model's).
double GroupMean(const Model& model, Param p);

// Multiplies the element group's values by `scale` and re-derives what depends on them
// (FinalizeModel). tool_k leaves the model as it is.
void ScaleGroup(Model& model, Param p, double scale);

// A part of the model a parameter may be fitted in: the elements whose midpoint at rest lies
// inside (as `idms-sim generate --inclusion` places a tumour). The .fem format has no labels, so
// a region is a shape.
struct Region {
  enum class Shape : uint8_t { kSphere, kBox };
  std::string name;  // from "NAME=...", else "region1", "region2", ... by position
  Shape shape = Shape::kSphere;
  double v[6] = {};  // sphere: cx, cy, cz, r; box: x0, y0, z0, x1, y1, z1 (corners, any order)
  bool Contains(const double* p) const;
};

// "[NAME=]sphere:cx,cy,cz,r" or "[NAME=]box:x0,y0,z0,x1,y1,z1"; index names an unnamed one
// ("region<index + 1>"). False with *error naming what is wrong.
bool ParseRegion(const std::string& spec, int index, Region* region, std::string* error);

// One fitted unknown: a parameter over its group of elements, within one part of the model.
// part -1: the whole model (no regions); 0 .. R-1: inside region `part` (the first that holds the
// element, in the order given); R: outside every region ("rest").
struct Unknown {
  Param param{};
  int part = -1;
};

// Where a fit has got to, for a caller that shows it (the server's fit jobs).
struct FitProgress {
  int iteration = 0;      // solver iterations done (Fit)
  int replays = 0;        // whole-trace replays so far
  double rms = 0;         // the force RMS error at the current estimate, force units (Fit)
  int presses_done = 0;   // FitMap: presses fitted so far
  int presses_total = 0;  // FitMap: presses found
};

struct FitOptions {
  std::vector<Param> params = {Param::kHomeK, Param::kSurfaceK};
  // With regions, every element parameter is fitted once per region and once outside them all.
  std::vector<Region> regions;
  StepOptions step;  // as the recording was made (idms-sim run's defaults)
  ToolCommand tool;  // kind, radius, stiffness, law, friction: as recorded (pos comes from the trace)
  int stride = 1;    // compare every stride-th tick (a replay steps every tick whatever it is)
  int max_iterations = 50;
  // The solver stops when an iteration improves the cost by less than this fraction of it.
  double function_tolerance = 1e-12;
  // Called on the fitting thread after every solver iteration (FitMap: after every press); false
  // stops the fit, which then ends not ok with the message "stopped". May be empty.
  std::function<bool(const FitProgress&)> progress;
  // Set (from any thread) to end the fit at its next replay, the solver's or the covariance's:
  // it then ends not ok with the message "stopped". May be null.
  const std::atomic<bool>* stop = nullptr;
};

struct FitResult {
  bool ok = false;
  std::string message;  // why not ok, or the solver's summary line
  std::vector<Unknown> unknowns;
  std::vector<std::string> names;   // per unknown: "home_k", or with regions "k@lump", "k@rest"
  std::vector<double> scale;        // fitted factor per unknown
  std::vector<double> scale_sigma;  // one standard deviation of the factor (from the covariance)
  std::vector<double> value;        // fitted group mean (typed-in mean * scale)
  std::vector<double> value_sigma;
  double rms_before = 0, rms_after = 0;  // force RMS error over the compared samples, force units
  double peak_force = 0;                 // largest |measured force|
  int samples = 0;                       // compared ticks
  int iterations = 0;
  int replays = 0;  // whole-trace replays the solver asked for
  double seconds = 0;
  Model fitted;                                     // the model with the fitted factors applied
  ToolCommand fitted_tool;                          // the tool with the fitted tool_k (as given without)
  std::vector<std::array<double, 3>> fitted_force;  // the replayed force at the fit, per compared sample
};

// Fits `model`'s groups to `trace`. Refuses (ok = false, message says why) a trace that never
// touches the model, a group (or a group within a region) with no elements or a zero typed-in
// mean, and a parameter the recording does not determine (a singular covariance).
FitResult Fit(const Model& model, const Trace& trace, const FitOptions& options);

// The stiffness map of a scan (`scripted:scan`, or any recording of separate presses): every press
// (a run of ticks in contact) is fitted on its own, one factor on every element's k from the
// ticks around it replayed from rest, and placed at the tool's x, y where the force peaked.
struct MapPoint {
  double x = 0, y = 0;
  double scale = 0, sigma = 0;  // apparent stiffness factor: the whole model's k x scale feels like this press
  double peak_force = 0;
  int64_t tick0 = 0, tick1 = 0;  // the replayed ticks [tick0, tick1)
};

// A lump: found when a press's factor stands out of the background (the median) by more than
// max(25% of it, 5 robust standard deviations of the scatter). Its centre, radius and stiffness
// ratio come from a profile fitted to every press: the background inside an isotropic step of
// the lump's height at a radius around a centre, smoothed by a logistic (Ceres, autodiff).
struct Lump {
  bool found = false;
  double x = 0, y = 0, xy_sigma = 0;  // centre, model units
  double radius = 0;                  // where the apparent stiffness is halfway up
  double ratio = 1, ratio_sigma = 0;  // the lump's stiffness over the background's
  int presses = 0;                    // presses above half the largest excess
};

struct MapResult {
  bool ok = false;
  std::string message;
  std::vector<MapPoint> points;
  double background = 0;  // median factor
  double spread = 0;      // 1.4826 x the median absolute deviation of the factors
  Lump lump;
  int replays = 0;
  double seconds = 0;
};

// options.params and options.regions are not used (the map fits k); the step, tool and stride are.
// Refuses a recording with fewer than 3 presses.
MapResult FitMap(const Model& model, const Trace& trace, const FitOptions& options);

// Replays the trace through Step on `model`; the device force at every stride-th tick (for the
// residuals and for a recording's synthetic twin in tests).
std::vector<std::array<double, 3>> Replay(const Model& model, const Trace& trace, const StepOptions& step,
                                          const ToolCommand& tool, int stride);

// A recording's synthetic twin, for tests, benches and the docs' figures: a shipped script's path
// (the thesis's sphere, r 1.5, k 400, on the default step; the pluck's tweezers, closed as its
// script says) at 1 kHz, the force `truth` gives along it, and Gaussian noise of `noise` times the
// peak force on every component (std::mt19937 `seed`). tool_stiffness: the tool's k in the recording.
Trace ScriptedTrace(const Model& truth, Script script, double noise, uint32_t seed, double tool_stiffness = 400);

}  // namespace idms::fit
