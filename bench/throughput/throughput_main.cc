// Full-model step throughput, one core: element updates per second at 10^3..10^6 atoms in
// double and float, against a memory-bandwidth bound measured in the same run (STREAM triad)
// and against Bullet's btSoftBody on the same network. Prints a table; never fails on time.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "runner.h"

namespace {

// STREAM triad a = b + s * c over arrays far larger than the caches; bytes/s counted as STREAM
// does (24 bytes per double element: two reads, one write). Median of `reps`.
double TriadBytesPerSecond(size_t n, int reps) {
  std::vector<double> a(n, 0.0), b(n, 1.0), c(n, 2.0);
  std::vector<double> rates;
  for (int r = 0; r < reps; ++r) {
    const double s = 0.5 + r;
    const auto start = std::chrono::steady_clock::now();
    for (size_t i = 0; i < n; ++i) a[i] = b[i] + s * c[i];
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    rates.push_back(24.0 * n / t);
  }
  volatile double sink = a[n / 2];
  (void)sink;
  std::sort(rates.begin(), rates.end());
  return rates[rates.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<long long> sizes = {1000, 10000, 100000, 1000000};
  double seconds = 0.5;
  int reps = 5;
  bool bullet = true;
  const char* csv_path = nullptr;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) sizes = {1000, 10000}, seconds = 0.1, reps = 3;
    else if (!std::strcmp(argv[i], "--no-bullet")) bullet = false;
    else if (!std::strcmp(argv[i], "--csv") && i + 1 < argc) csv_path = argv[++i];
    else {
      std::fprintf(stderr, "usage: %s [--quick] [--no-bullet] [--csv FILE]\n", argv[0]);
      return 2;
    }
  }

  const double triad = TriadBytesPerSecond(size_t{40} << 20, 7);
  std::printf("STREAM triad (one core, 3 x 320 MiB): %.2f GB/s (median of 7)\n\n", triad / 1e9);
  std::printf("%9s %9s | %12s %7s %6s | %12s %7s %6s | %12s %8s\n", "atoms", "elements", "double el/s", "B/el",
              "bound", "float el/s", "B/el", "bound", "bullet el/s", "f32/blt");
  std::FILE* csv = csv_path ? std::fopen(csv_path, "w") : nullptr;
  if (csv) std::fprintf(csv, "atoms,elements,double_el_per_s,double_bytes_per_el,double_bound_ratio,float_el_per_s,float_bytes_per_el,float_bound_ratio,bullet_el_per_s,triad_bytes_per_s\n");
  for (long long n : sizes) {
    const ThroughputResult d = RunThroughputDouble(n, seconds, reps);
    const ThroughputResult f = RunThroughputFloat(n, seconds, reps);
    int64_t links = 0;
    const double b = bullet ? RunBulletSoftBody(n, seconds, reps, &links) : 0;
    // Bound: the triad rate divided by the bytes an element update must move.
    const double d_ratio = d.elem_updates_per_s / (triad / d.bytes_per_elem);
    const double f_ratio = f.elem_updates_per_s / (triad / f.bytes_per_elem);
    std::printf("%9lld %9lld | %12.3e %7.1f %5.0f%% | %12.3e %7.1f %5.0f%% | ", static_cast<long long>(d.atoms),
                static_cast<long long>(d.elements), d.elem_updates_per_s, d.bytes_per_elem, 100 * d_ratio,
                f.elem_updates_per_s, f.bytes_per_elem, 100 * f_ratio);
    if (b > 0) std::printf("%12.3e %7.1fx\n", b, f.elem_updates_per_s / b);
    else std::printf("%12s %8s\n", "n/a", "n/a");
    if (csv) {
      std::fprintf(csv, "%lld,%lld,%.6g,%.3g,%.4f,%.6g,%.3g,%.4f,%.6g,%.6g\n", static_cast<long long>(d.atoms),
                   static_cast<long long>(d.elements), d.elem_updates_per_s, d.bytes_per_elem, d_ratio,
                   f.elem_updates_per_s, f.bytes_per_elem, f_ratio, b, triad);
    }
    std::fflush(stdout);
  }
  if (csv) std::fclose(csv);
  std::printf("\nbound = measured rate / (triad bytes/s / bytes an update must move); el/s = element updates per second\n");
  return 0;
}
