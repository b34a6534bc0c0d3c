// idms-sim: model generation, validation, offline runs and stability analysis of the DSM.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <utility>
#include <vector>

#include "command.h"

namespace idms::tool {
namespace {

std::vector<std::pair<int, CommandSetup>>& Registry() {
  static std::vector<std::pair<int, CommandSetup>> registry;
  return registry;
}

}  // namespace

CommandRegistrar::CommandRegistrar(int order, CommandSetup setup) { Registry().emplace_back(order, setup); }

void PrintJson(const nlohmann::json& j) { std::cout << j.dump() << std::endl; }

void Fail(const std::string& command, const std::string& message) {
  std::cerr << "idms-sim " << command << ": " << message << std::endl;
  throw CLI::RuntimeError(1);
}

}  // namespace idms::tool

int main(int argc, char** argv) {
  CLI::App app{"idms-sim: generate, validate, run and analyse Discrete Simulation Models (Swarup 1995)"};
  app.require_subcommand(1);
  auto& registry = idms::tool::Registry();
  std::stable_sort(registry.begin(), registry.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& entry : registry) entry.second(app);
  CLI11_PARSE(app, argc, argv);
  return 0;
}
