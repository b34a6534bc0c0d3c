// Writes what idms-render makes of protocol/display.json, as JSON, for display.test.mjs to
// compare with viewer-web's view/display.js: per model (loaded as idms-render loads one) its rest
// surface, displacement range and per-vertex stiffness, and for a list of displacements the
// colour-map entry and the colour idms-render draws.
//   idms-web-display-colours MODELS_DIR NAME... > OUT.json
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>

#include "idms/render/display.h"
#include "idms/render/source.h"

int main(int argc, char** argv) {
  using nlohmann::json;
  using namespace idms::render;
  if (argc < 3) {
    std::fprintf(stderr, "usage: idms-web-display-colours MODELS_DIR NAME...\n");
    return 1;
  }
  json out;
  for (int i = 2; i < argc; ++i) {
    ViewerState state;
    std::string error;
    if (!LoadRestState(std::string(argv[1]) + "/" + argv[i], &state, &error)) {
      std::fprintf(stderr, "%s: %s\n", argv[i], error.c_str());
      return 2;
    }
    const auto positions = state.mirror.positions();
    const auto triangles = state.mirror.triangles();
    const double hi = DisplacementRange(positions, triangles);
    json colours = json::array();
    // Around every entry's boundaries and beyond the range, and the palpation's depths.
    std::vector<double> d = {0, 1e-4, 0.01, 0.025, 0.05, 0.063, 0.1, 0.2, 1.5, -1};
    for (int k = 0; k <= 255; k += 17) d.push_back(hi * (k + 0.5) / 255), d.push_back(hi * (k + 0.4999) / 255);
    for (const double v : d) {
      const int index = ColourIndex(v, 0, hi);
      const Srgb& c = TheDisplay().map[static_cast<size_t>(index)];
      colours.push_back({{"displacement", v}, {"index", index}, {"srgb", {c[0], c[1], c[2]}}});
    }
    out[argv[i]] = {{"positions", std::vector<float>(positions.begin(), positions.end())},
                    {"triangles", std::vector<int32_t>(triangles.begin(), triangles.end())},
                    {"range", hi},
                    {"stiffness", state.stiffness},
                    {"colours", colours}};
  }
  std::cout << out.dump() << "\n";
  return 0;
}
