// idms-sim reorder: renumber a model for memory locality (atoms reverse Cuthill-McKee, elements
// in the full-mode step's walk order) and write it as a new fem/plg pair.
#include <cstdio>

#include "command.h"
#include "idms/sim/model_io.h"
#include "idms/sim/reorder.h"

namespace idms::tool {
namespace {

void Setup(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "reorder", "Renumber a model so that full-mode steps stream memory in order (a new fem/plg pair)");
  static std::string model_prefix, out;
  static bool keep_atoms = false;
  cmd->add_option("--model", model_prefix, "Input prefix (PREFIX.fem and PREFIX.plg)")->required();
  cmd->add_option("--out", out, "Output prefix: writes PREFIX.fem and PREFIX.plg")->required();
  cmd->add_flag("--keep-atom-order", keep_atoms, "Renumber elements only (atom ids, and so the plg, unchanged)");
  cmd->callback([] {
    std::string fem, plg;
    ModelPaths(model_prefix, &fem, &plg);
    Model model;
    LoadError load_error;
    if (!LoadModel(fem, plg, ReadOptions{}, &model, &load_error)) {
      std::fprintf(stderr, "%s\n", load_error.ToString().c_str());
      throw CLI::RuntimeError(1);
    }
    const Model reordered = ReorderForLocality(model, ReorderOptions{.atoms = !keep_atoms});
    std::string error;
    if (!SaveModel(reordered, out, &error)) Fail("reorder", error);
    std::printf("wrote %s.fem and %s.plg (%d atoms, %d elements, %s)\n", out.c_str(), out.c_str(), reordered.num_atoms,
                reordered.num_elems, keep_atoms ? "elements renumbered" : "atoms and elements renumbered");
  });
}

IDMS_SIM_COMMAND(25, Setup);

}  // namespace
}  // namespace idms::tool
