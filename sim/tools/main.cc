// idms-sim: model generation, validation, offline runs and stability analysis of the DSM.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <utility>
#include <vector>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "command.h"
#include "idms/protocol/cli.h"

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
#if defined(__GLIBC__)
  // Large arrays from the heap rather than each from its own mmap: glibc maps every block past
  // its threshold (128 KiB at start) to start 16 bytes into a page, so the ~20 arrays that full
  // mode's fused pass streams side by side all sit at the same offset of a page, and `run --full`
  // on 10^6 atoms ran at 6.5e7 element updates per second instead of 1.1e8, on the same model
  // (docs/performance.md). The throughput bench escaped it by chance: its frees had already
  // raised glibc's adaptive threshold.
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
#endif
  CLI::App app{"idms-sim: generate, validate, run and analyse Discrete Simulation Models (Swarup 1995)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", idms::Version());
  auto& registry = idms::tool::Registry();
  std::stable_sort(registry.begin(), registry.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& entry : registry) entry.second(app);
  CLI11_PARSE(app, argc, argv);
  return 0;
}
