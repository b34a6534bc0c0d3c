// The fitter's figures (issue 34, docs/fit.md): parameters hidden in synthetic recordings of every
// shipped sphere script on the hex fragment, with Gaussian noise of 1% of the peak force, fitted
// back; how close each comes (fitted / hidden) with its one-sigma uncertainty, the residual, and
// what the fit cost; then per region (an inclusion on the stroke's line) and the stiffness map of
// a scan of slab_40x40_tumour and of the plain slab. Deterministic but for the times. --quick: the
// palpation and the gentle stroke.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "fit.h"
#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"

namespace {

bool Load(const char* name, idms::Model* m) {
  idms::LoadError error;
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/" + name;
  if (idms::LoadModel(prefix + ".fem", prefix + ".plg", {}, m, &error)) return true;
  std::fprintf(stderr, "%s\n", error.ToString().c_str());
  return false;
}

// Per region: k x 3.3 inside a sphere of radius 0.9 on the fragment's stroke line, x 1.1 outside;
// and the scans' maps.
int RegionsAndMaps(const idms::Model& typed) {
  using namespace idms;
  using namespace idms::fit;
  Model truth = typed;
  Inclusion lump;
  lump.center[0] = 2, lump.center[1] = 1.5, lump.radius = 0.9, lump.k_scale = 3;
  ApplyInclusions({lump}, &truth);
  ScaleGroup(truth, Param::kK, 1.1);
  FitOptions o;
  o.params = {Param::kK};
  o.tool.kind = ToolKind::kSphere;
  Region region;
  std::string error;
  if (!ParseRegion("lump=sphere:2,1.5,0,0.9", 0, &region, &error)) return 1;
  o.regions = {region};
  std::printf("\nper region: hex fragment, hidden k x3.3 inside sphere 2,1.5,0 r 0.9, x1.1 outside; noise 1%%\n");
  for (Script script : {Script::kStrokeGentle, Script::kPalpate}) {
    const FitResult r = Fit(typed, ScriptedTrace(truth, script, 0.01, 7), o);
    if (!r.ok) {
      std::printf("%-14s %s\n", ScriptName(script), r.message.c_str());
      continue;
    }
    std::printf("%-14s k@lump %.4f +- %.4f   k@rest %.4f +- %.4f  (fitted / hidden)   %.2f s\n", ScriptName(script),
                r.scale[0] / 3.3, r.scale_sigma[0] / 3.3, r.scale[1] / 1.1, r.scale_sigma[1] / 1.1, r.seconds);
  }
  Model plain, tumour;
  if (!Load("slab_40x40", &plain) || !Load("slab_40x40_tumour", &tumour)) return 1;
  std::printf("\nstiffness map: 7 x 7 scan (scripted:scan), noise 1%%, seed 11, mapped against slab_40x40\n");
  std::printf("%-18s %7s %9s | %5s %8s %8s %7s %7s %6s | %7s %6s\n", "recording", "presses", "backgr", "lump", "x", "y",
              "radius", "ratio", "sigma", "replays", "s");
  for (const auto& [name, truth_model] : {std::pair<const char*, const Model*>{"slab_40x40_tumour", &tumour},
                                          std::pair<const char*, const Model*>{"slab_40x40", &plain}}) {
    const MapResult m = FitMap(plain, ScriptedTrace(*truth_model, Script::kScan, 0.01, 11), o);
    if (!m.ok) {
      std::printf("%-18s %s\n", name, m.message.c_str());
      continue;
    }
    std::printf("%-18s %7zu %9.4f | %5s %8.3f %8.3f %7.3f %7.3f %6.2g | %7d %6.2f\n", name, m.points.size(),
                m.background, m.lump.found ? "yes" : "no", m.lump.x, m.lump.y, m.lump.radius, m.lump.ratio,
                m.lump.ratio_sigma, m.replays, m.seconds);
  }
  std::printf("(slab_40x40_tumour: k x 8 in a sphere of radius 4 at 20, 17, -0.4)\n");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace idms;
  using namespace idms::fit;
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  Model typed;
  LoadError error;
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  if (!LoadModel(prefix + ".fem", prefix + ".plg", {}, &typed, &error)) {
    std::fprintf(stderr, "%s\n", error.ToString().c_str());
    return 1;
  }
  // The hidden model: the home springs 30% stiffer and 20% more damped, the surface 20% softer.
  const std::vector<Param> params = {Param::kHomeK, Param::kSurfaceK, Param::kHomeB};
  const double hidden[] = {1.3, 0.8, 1.2};
  Model truth = typed;
  for (size_t i = 0; i < params.size(); ++i) ScaleGroup(truth, params[i], hidden[i]);
  std::printf("hex fragment, hidden home_k x1.3, surface_k x0.8, home_b x1.2; noise 1%% of the peak force, seed 7\n");
  std::printf("fitted / hidden (+- one sigma, from the covariance)\n");
  std::printf("%-14s %6s | %-17s %-17s %-17s | %9s %9s | %5s %7s %6s\n", "script", "peak", "home_k", "surface_k",
              "home_b", "rms typed", "rms fit", "iters", "replays", "s");
  std::vector<Script> scripts = {Script::kPalpate, Script::kStrokeGentle};
  if (!quick) scripts = {Script::kPalpate, Script::kStrokeGentle, Script::kStrokeSlow, Script::kStrokeFast};
  for (Script script : scripts) {
    const Trace trace = ScriptedTrace(truth, script, 0.01, 7);
    FitOptions o;
    o.params = params;
    o.tool.kind = ToolKind::kSphere;
    const FitResult r = Fit(typed, trace, o);
    if (!r.ok) {
      std::printf("%-14s %s\n", ScriptName(script), r.message.c_str());
      continue;
    }
    std::printf("%-14s %6.3g |", ScriptName(script), r.peak_force);
    for (size_t i = 0; i < params.size(); ++i) {
      std::printf(" %.4f +- %.4f  ", r.scale[i] / hidden[i], r.scale_sigma[i] / hidden[i]);
    }
    std::printf("| %9.3g %9.3g | %5d %7d %6.2f\n", r.rms_before, r.rms_after, r.iterations, r.replays, r.seconds);
  }
  // One stiffness from a palpation, and what it predicts of a stroke it did not see.
  Model truth_one = typed;
  ScaleGroup(truth_one, Param::kHomeK, 1.3);
  FitOptions one;
  one.params = {Param::kHomeK};
  one.tool.kind = ToolKind::kSphere;
  const auto start = std::chrono::steady_clock::now();
  const FitResult r = Fit(typed, ScriptedTrace(truth_one, Script::kPalpate, 0.01, 7), one);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!r.ok) {
    std::printf("palpation, home_k alone: %s\n", r.message.c_str());
    return 1;
  }
  const Trace stroke = ScriptedTrace(truth_one, Script::kStrokeGentle, 0.0, 7);
  const auto predicted = Replay(r.fitted, stroke, StepOptions{}, one.tool, 1);
  double sum = 0, peak = 0;
  for (size_t n = 0; n < predicted.size(); ++n) {
    const auto& f = stroke.force[n];
    peak = std::max(peak, std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
    for (int c = 0; c < 3; ++c) sum += (predicted[n][c] - f[c]) * (predicted[n][c] - f[c]);
  }
  std::printf(
      "palpation, home_k alone (hidden x1.3): fitted / hidden %.4f +- %.4f in %.2f s; the held-out gentle stroke "
      "predicted with relative RMS error %.4f\n",
      r.scale[0] / 1.3, r.scale_sigma[0] / 1.3, s, std::sqrt(sum / static_cast<double>(predicted.size())) / peak);
  return quick ? 0 : RegionsAndMaps(typed);
}
