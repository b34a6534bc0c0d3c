// How fast the thesis's strokes were (thesis 6.1.2, figures 6-5 and 6-6), read off this model:
// the seed has the figures' captions and text but not their plots, so the speeds are found as the
// ones at which the hex fragment gives the forces the text reports. The stroke of the scripts
// (down between t = 1 and 3 s, 0.11 below contact, then across the 2.4-unit stroke line with the
// scripts' half-cosine easing) is run with its crossing time D swept, three crossings each, and
// the table prints, per D: the peak speed, max |f_x| and |f_y| while crossing, mean f_z, and the
// inertial part of f_x while accelerating and while decelerating (the first crossing's halves): f_x minus a
// quasi-static crossing's f_x at the same x (D = 40 s), which takes out what the discrete surface alone gives (0.26 N
// with the tool still). The thesis: slow stroke, f_x "increases to -0.1 N" while accelerating; fast stroke, |f_x|
// "almost 2 N" each traversal, f_y "increases dramatically", f_z "similar". Deterministic; prints figures.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <string>
#include <vector>

#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"
#include "idms/sim/preset.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace {

using namespace idms;

constexpr double kDepth = 0.11;  // below first contact, as the stroke scripts
constexpr double kPressedAt = 3.0;
constexpr int kCrossings = 3;

struct Row {
  double crossing_s = 0, peak_speed = 0, max_fx = 0, max_fy = 0, mean_fz = 0, inertial_fx_accel = 0,
         inertial_fx_decel = 0;
  int64_t warnings = 0;
};

// x as a fraction of the stroke line at time t: there and back, half-cosine eased per crossing.
double StrokeFraction(double t, double crossing_s) {
  if (t <= kPressedAt) return 0;
  const double u = std::min((t - kPressedAt) / crossing_s, static_cast<double>(kCrossings));
  const int leg = std::min(static_cast<int>(u), kCrossings - 1);
  const double s = 0.5 * (1 - std::cos(std::numbers::pi * (u - leg)));
  return leg % 2 == 0 ? s : 1 - s;
}

// One run; with `quasi` set, records f_x against x over the first crossing, else compares with it.
Row Run(const Model& model, Preset preset, double crossing_s, std::vector<std::array<double, 2>>* quasi) {
  const ScriptGeometry g = MakeScriptGeometry(model, 1.5);
  const PresetSettings settings = SettingsOf(preset);
  StepOptions o;
  o.integrator = settings.integrator;
  o.local_radius = settings.local_radius_per_tool_radius * 1.5;
  State s = MakeState(model);
  Workspace w = MakeWorkspace(model, o);
  ToolInput input;
  input.num_tools = 1;
  ToolCommand& tool = input.tools[0];
  tool.kind = ToolKind::kSphere;
  const bool record = quasi->empty();
  Row row{.crossing_s = crossing_s, .peak_speed = std::numbers::pi / 2 * (g.x_max - g.x_min) / crossing_s};
  double sum_fz = 0, sum_accel = 0, sum_decel = 0;
  int64_t n = 0, n_accel = 0, n_decel = 0;
  const double z_contact = g.top_z + g.mio_radius;
  const double end = kPressedAt + kCrossings * crossing_s;
  for (int64_t k = 1; k * o.dt_s <= end + 1e-9; ++k) {
    const double t = k * o.dt_s;
    const double down = std::clamp((t - 1.0) / 2.0, 0.0, 1.0);
    const double x = StrokeFraction(t, crossing_s);
    tool.pos[0] = g.x_min + x * (g.x_max - g.x_min);
    tool.pos[1] = g.stroke_y;
    tool.pos[2] = z_contact + 1.0 - (1.0 + kDepth) * 0.5 * (1 - std::cos(std::numbers::pi * down));
    const StepReport r = Step(model, s, w, input);
    const double* f = r.tools[0].force;
    if (t <= kPressedAt) continue;
    row.max_fx = std::max(row.max_fx, std::abs(f[0]));
    row.max_fy = std::max(row.max_fy, std::abs(f[1]));
    sum_fz += f[2], ++n;
    if (t > kPressedAt + crossing_s) continue;  // the first crossing only, below
    if (record) {
      quasi->push_back({x, f[0]});
    } else {
      const auto it = std::lower_bound(quasi->begin(), quasi->end(), std::array<double, 2>{x, -INFINITY});
      const double inertial = f[0] - (it == quasi->end() ? quasi->back() : *it)[1];
      if (t < kPressedAt + 0.5 * crossing_s) {
        sum_accel += inertial, ++n_accel;
      } else {
        sum_decel += inertial, ++n_decel;
      }
    }
  }
  row.mean_fz = n ? sum_fz / static_cast<double>(n) : 0;
  row.inertial_fx_accel = n_accel ? sum_accel / static_cast<double>(n_accel) : 0;
  row.inertial_fx_decel = n_decel ? sum_decel / static_cast<double>(n_decel) : 0;
  row.warnings = TotalWarnings(s.warnings);
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  bool quick = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) {
      quick = true;
    } else if (!std::strcmp(argv[i], "--model") && i + 1 < argc) {
      prefix = argv[++i];
    } else {
      std::fprintf(stderr, "usage: %s [--quick] [--model PREFIX]\n", argv[0]);
      return 2;
    }
  }
  Model model;
  LoadError error;
  if (!LoadModel(prefix + ".fem", prefix + ".plg", {}, &model, &error)) {
    std::fprintf(stderr, "%s\n", error.ToString().c_str());
    return 1;
  }
  const std::vector<double> times =
      quick ? std::vector<double>{0.3, 0.1} : std::vector<double>{4.0, 1.2, 0.6, 0.3, 0.2, 0.15, 0.1, 0.07};
  for (Preset preset : {Preset::kThesis, Preset::kDefault}) {
    std::printf("%s preset (%s, r_l %.2f), hex fragment, stroke %.2f below contact, %d crossings:\n",
                PresetName(preset), IntegratorName(SettingsOf(preset).integrator),
                1.5 * SettingsOf(preset).local_radius_per_tool_radius, kDepth, kCrossings);
    std::printf("  %10s %11s %10s %10s %10s %12s %12s %8s\n", "crossing_s", "peak_u_per_s", "max|f_x|", "max|f_y|",
                "mean_f_z", "inertial_acc", "inertial_dec", "warnings");
    std::vector<std::array<double, 2>> quasi;
    Run(model, preset, 40.0, &quasi);
    for (double d : times) {
      const Row r = Run(model, preset, d, &quasi);
      std::printf("  %10.3f %11.1f %10.3f %10.3f %10.3f %12.3f %12.3f %8lld\n", r.crossing_s, r.peak_speed, r.max_fx,
                  r.max_fy, r.mean_fz, r.inertial_fx_accel, r.inertial_fx_decel, static_cast<long long>(r.warnings));
    }
  }
  return 0;
}
