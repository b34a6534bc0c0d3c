// idms-sim generate slab: the two-layer tetrahedral slab of thesis figure 3-1, with inclusions.
#include <sstream>

#include "command.h"
#include "idms/sim/generate.h"
#include "idms/sim/model_io.h"

namespace idms::tool {
namespace {

// "X,Y,Z,RADIUS,K_SCALE,MASS_SCALE" -> Inclusion.
bool ParseInclusion(const std::string& text, Inclusion* inc, std::string* error) {
  std::stringstream in(text);
  double v[6];
  char comma;
  for (int i = 0; i < 6; ++i) {
    if (!(in >> v[i]) || (i < 5 && !(in >> comma && comma == ','))) {
      *error = "--inclusion '" + text + "': expected X,Y,Z,RADIUS,K_SCALE,MASS_SCALE (six numbers)";
      return false;
    }
  }
  if (v[3] <= 0 || v[4] <= 0 || v[5] <= 0) {
    *error = "--inclusion '" + text + "': expected RADIUS, K_SCALE and MASS_SCALE > 0";
    return false;
  }
  *inc = {{v[0], v[1], v[2]}, v[3], v[4], v[5]};
  return true;
}

void Setup(CLI::App& app) {
  auto* generate = app.add_subcommand("generate", "Generate a model (thesis 5.6)");
  generate->require_subcommand(1);
  auto* slab = generate->add_subcommand("slab", "Two-layer tetrahedral slab with home elements (thesis fig. 3-1)");
  static SlabOptions options;
  static std::vector<std::string> inclusions;
  static std::string out;
  slab->add_option("--rows", options.rows, "Rows of the top hex grid")->required()->check(CLI::Range(2, 100000));
  slab->add_option("--cols", options.cols, "Atoms in even rows (odd rows have one more)")
      ->required()
      ->check(CLI::Range(1, 100000));
  slab->add_option("--spacing", options.spacing, "Element length of the top grid")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  slab->add_option("--k", options.k, "Element stiffness")->check(CLI::NonNegativeNumber)->capture_default_str();
  slab->add_option("--b", options.b, "Element viscosity")->check(CLI::NonNegativeNumber)->capture_default_str();
  slab->add_option("--mass", options.mass, "Atom mass")->check(CLI::PositiveNumber)->capture_default_str();
  slab->add_option("--home-k", options.home_k, "Home element stiffness")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  slab->add_option("--home-b", options.home_b, "Home element viscosity")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  slab->add_option("--decimals", options.decimals, "Round positions to this many decimals (-1: exact)")
      ->capture_default_str();
  slab->add_option("--name", options.name, "Model name written in the headers")->capture_default_str();
  slab->add_option("--inclusion", inclusions, "Stiff, heavy region X,Y,Z,RADIUS,K_SCALE,MASS_SCALE (repeatable)");
  slab->add_option("--out", out, "Output prefix: writes PREFIX.fem and PREFIX.plg")->required();
  slab->callback([] {
    for (const std::string& text : inclusions) {
      Inclusion inc;
      std::string error;
      if (!ParseInclusion(text, &inc, &error)) Fail("generate slab", error);
      options.inclusions.push_back(inc);
    }
    const Model model = GenerateSlab(options);
    std::string error;
    if (!SaveModel(model, out, &error)) Fail("generate slab", error);
    std::cout << "wrote " << out << ".fem (" << model.num_atoms << " atoms, " << model.num_elems << " elements) and "
              << out << ".plg (" << model.num_external << " vertices, " << model.num_tris << " triangles)\n";
  });
}

IDMS_SIM_COMMAND(10, Setup);

}  // namespace
}  // namespace idms::tool
