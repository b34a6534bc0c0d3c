// idms-sim validate: load a .fem (and .plg / .obj), print its summary or the first error.
#include <cstdio>

#include "command.h"
#include "idms/sim/model_io.h"
#include "idms/sim/summary.h"

namespace idms::tool {
namespace {

nlohmann::json SummaryJson(const ModelSummary& s) {
  return {{"atoms", s.atoms},
          {"free_atoms", s.free_atoms},
          {"fixed_atoms", s.fixed_atoms},
          {"external_atoms", s.external_atoms},
          {"elements", s.elements},
          {"home_elements", s.home_elements},
          {"triangles", s.triangles},
          {"bbox_min", {s.bbox_min[0], s.bbox_min[1], s.bbox_min[2]}},
          {"bbox_max", {s.bbox_max[0], s.bbox_max[1], s.bbox_max[2]}},
          {"total_mass", s.total_mass},
          {"k_min", s.k_min},
          {"k_max", s.k_max},
          {"b_min", s.b_min},
          {"b_max", s.b_max},
          {"stable_dt_euler", s.stable_dt_euler},
          {"stable_dt_symplectic", s.stable_dt_symplectic}};
}

void PrintText(const std::string& name, const ModelSummary& s) {
  std::printf("model %s\n", name.c_str());
  std::printf("  atoms          %d (%d free, %d fixed, %d external)\n", s.atoms, s.free_atoms, s.fixed_atoms,
              s.external_atoms);
  std::printf("  elements       %d (%d home)\n", s.elements, s.home_elements);
  std::printf("  triangles      %d\n", s.triangles);
  std::printf("  bounding box   (%g, %g, %g) .. (%g, %g, %g)\n", s.bbox_min[0], s.bbox_min[1], s.bbox_min[2],
              s.bbox_max[0], s.bbox_max[1], s.bbox_max[2]);
  std::printf("  total mass     %g\n", s.total_mass);
  std::printf("  stiffness      %g .. %g\n", s.k_min, s.k_max);
  std::printf("  viscosity      %g .. %g\n", s.b_min, s.b_max);
  std::printf("  stable dt      explicit Euler %g s, symplectic Euler %g s (Gershgorin bound)\n", s.stable_dt_euler,
              s.stable_dt_symplectic);
}

void Setup(CLI::App& app) {
  auto* cmd = app.add_subcommand("validate", "Check a model's files and print its summary (or the first error)");
  static std::string fem, plg;
  static bool json = false;
  static ReadOptions options;
  cmd->add_option("fem", fem, "The .fem file (or its prefix)")->required();
  cmd->add_option("plg", plg, "The .plg or .obj surface (default: none)");
  cmd->add_option("--max-bytes", options.max_bytes, "Refuse files larger than this")->capture_default_str();
  cmd->add_option("--tolerance", options.plg_tolerance, "Max distance between plg vertex and fem atom")
      ->capture_default_str();
  cmd->add_flag("--json", json, "Print the summary as one JSON object");
  cmd->callback([] {
    std::string fem_path = fem, unused;
    if (fem_path.size() < 4 || fem_path.compare(fem_path.size() - 4, 4, ".fem") != 0)
      ModelPaths(fem, &fem_path, &unused);
    Model model;
    LoadError error;
    if (!LoadModel(fem_path, plg, options, &model, &error)) {
      std::fprintf(stderr, "%s\n", error.ToString().c_str());
      throw CLI::RuntimeError(1);
    }
    const ModelSummary summary = Summarize(model);
    if (json) {
      PrintJson(SummaryJson(summary));
    } else {
      PrintText(model.name, summary);
    }
  });
}

IDMS_SIM_COMMAND(20, Setup);

}  // namespace
}  // namespace idms::tool
