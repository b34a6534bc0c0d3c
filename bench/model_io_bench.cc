// Parse and write throughput (MB/s) of .fem/.plg, and memory per atom, for slabs of 10^4 to
// 10^6 atoms generated in the run (never committed). Prints figures; never fails on time.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "idms/sim/generate.h"
#include "idms/sim/model_io.h"

namespace idms {
namespace {

// A square slab of about `atoms` atoms (3 atoms per top grid site: top, home, apex).
const Model& Slab(int64_t atoms) {
  static std::map<int64_t, Model> cache;
  auto it = cache.find(atoms);
  if (it == cache.end()) {
    const int32_t side = static_cast<int32_t>(std::lround(std::sqrt(atoms / 3.0)));
    it = cache.emplace(atoms, GenerateSlab(SlabOptions{.rows = side, .cols = side})).first;
  }
  return it->second;
}

void BM_WriteFem(benchmark::State& state) {
  const Model& model = Slab(state.range(0));
  size_t bytes = 0;
  for (auto _ : state) {
    const std::string text = WriteFem(model) + WritePlg(model);
    bytes = text.size();
    benchmark::DoNotOptimize(text.data());
  }
  state.SetBytesProcessed(static_cast<int64_t>(bytes) * state.iterations());
  state.counters["atoms"] = model.num_atoms;
  state.counters["file_MB"] = bytes / 1e6;
}

void BM_ParseFem(benchmark::State& state) {
  const Model& model = Slab(state.range(0));
  const std::string fem = WriteFem(model), plg = WritePlg(model);
  Model parsed;
  for (auto _ : state) {
    SurfaceMesh mesh;
    LoadError error;
    if (!ParseFem(fem, "bench.fem", &parsed, &error) || !ParsePlg(plg, "bench.plg", &mesh, &error) ||
        !AttachSurface(mesh, "bench.plg", 1e-9, &parsed, &error)) {
      state.SkipWithError(error.ToString().c_str());
      return;
    }
  }
  state.SetBytesProcessed(static_cast<int64_t>(fem.size() + plg.size()) * state.iterations());
  state.counters["atoms"] = parsed.num_atoms;
  state.counters["elements"] = parsed.num_elems;
  // Memory held by the loaded model, per atom (capacity of every array).
  state.counters["model_bytes_per_atom"] = static_cast<double>(ModelBytes(parsed)) / parsed.num_atoms;
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  state.counters["peak_rss_MB"] = usage.ru_maxrss / 1024.0;
}

BENCHMARK(BM_WriteFem)->Arg(10'000)->Arg(100'000)->Arg(1'000'000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ParseFem)->Arg(10'000)->Arg(100'000)->Arg(1'000'000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace idms

BENCHMARK_MAIN();
