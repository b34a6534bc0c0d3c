// Full-model step throughput, one core: element updates per second at 10^3..10^6 atoms in
// double and float, against a memory-bandwidth bound measured in the same run (STREAM triad),
// against the general path on the same model, and against Bullet's btSoftBody on the same
// network. Prints a table (and CSV with --csv); never fails on time.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "runner.h"

double ThreadCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

namespace {

// Median of `passes` triads over the given arrays (see runner.h).
double Triad(std::vector<double>& a, const std::vector<double>& b, const std::vector<double>& c, int passes) {
  const size_t n = a.size();
  std::vector<double> rates;
  for (int r = 0; r < passes; ++r) {
    const double s = 0.5 + r;
    const double start = ThreadCpuSeconds();
    for (size_t i = 0; i < n; ++i) a[i] = b[i] + s * c[i];
    rates.push_back(24.0 * static_cast<double>(n) / (ThreadCpuSeconds() - start));
  }
  volatile double sink = a[n / 2];
  (void)sink;
  std::sort(rates.begin(), rates.end());
  return rates[rates.size() / 2];
}

// The paired triad's arrays: 3 x 128 MiB, allocated and touched once.
struct TriadArrays {
  std::vector<double> a, b, c;
};
TriadArrays& PairedArrays() {
  static TriadArrays t{std::vector<double>(size_t{16} << 20, 0.0), std::vector<double>(size_t{16} << 20, 1.0),
                       std::vector<double>(size_t{16} << 20, 2.0)};
  return t;
}

}  // namespace

double TriadSample() {
  TriadArrays& t = PairedArrays();
  return Triad(t.a, t.b, t.c, 3);
}

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double TriadSampleThreads(int threads) {
  TriadArrays& t = PairedArrays();
  const size_t n = t.a.size();
  std::vector<double> rates;
  for (int r = 0; r < 3; ++r) {
    const double s = 0.5 + r;
    const double start = WallSeconds();
    std::vector<std::thread> pool;
    for (int i = 0; i < threads; ++i) {
      pool.emplace_back([&, i] {
        for (size_t j = n * i / threads, end = n * (i + 1) / threads; j < end; ++j) t.a[j] = t.b[j] + s * t.c[j];
      });
    }
    for (std::thread& th : pool) th.join();
    rates.push_back(24.0 * static_cast<double>(n) / (WallSeconds() - start));
  }
  std::sort(rates.begin(), rates.end());
  return rates[1];
}

namespace {

// --threads N: the fused pass on one thread and on N, wall clock, each repetition against a triad
// on as many threads; the speed-up and the fraction of the N-thread bandwidth bound.
int RunThreads(const std::vector<long long>& sizes, int threads, double seconds, int reps, bool f64, bool f32,
               bool huge, bool check) {
  std::printf(
      "full model, symplectic Euler, eq. 4.6 filter on, energy check %s; slabs renumbered; wall clock, median of %d;\n"
      "each repetition paired with a triad (3 x 128 MiB) on as many threads, taken just before it\n\n",
      check ? "on" : "off", reps);
  std::printf("%9s %9s %4s | %10s %10s %6s %5s | %10s %10s %6s %5s | %7s %7s\n", "atoms", "elements", "sect",
              "f64 1 thr", "f64 N thr", "ratio", "bound", "f32 1 thr", "f32 N thr", "ratio", "bound", "triad 1",
              "triad N");
  for (long long n : sizes) {
    const ThroughputVariant one{.huge_pages = huge, .energy_check = check, .threads = 1, .wall = true};
    ThroughputVariant many = one;
    many.threads = threads;
    const ThroughputResult d1 = f64 ? RunThroughputDouble(n, seconds, reps, one) : ThroughputResult{};
    const ThroughputResult dn = f64 ? RunThroughputDouble(n, seconds, reps, many) : ThroughputResult{};
    const ThroughputResult f1 = f32 ? RunThroughputFloat(n, seconds, reps, one) : ThroughputResult{};
    const ThroughputResult fn = f32 ? RunThroughputFloat(n, seconds, reps, many) : ThroughputResult{};
    auto ratio = [](const ThroughputResult& a, const ThroughputResult& b) {
      return b.elem_updates_per_s > 0 ? a.elem_updates_per_s / b.elem_updates_per_s : 0.0;
    };
    const ThroughputResult& any = f64 ? dn : fn;
    std::printf("%9lld %9lld %4d | %10.3e %10.3e %5.2fx %4.0f%% | %10.3e %10.3e %5.2fx %4.0f%% | %7.2f %7.2f\n",
                static_cast<long long>(any.atoms), static_cast<long long>(any.elements), any.sections,
                d1.elem_updates_per_s, dn.elem_updates_per_s, ratio(dn, d1), 100 * dn.bound_ratio,
                f1.elem_updates_per_s, fn.elem_updates_per_s, ratio(fn, f1), 100 * fn.bound_ratio,
                (f64 ? d1 : f1).triad_bytes_per_s / 1e9, any.triad_bytes_per_s / 1e9);
    std::fflush(stdout);
  }
  std::printf(
      "\nel/s = element updates per wall-clock second; sect = sections the N-thread pass ran in; ratio = N threads\n"
      "over one; bound = el/s x bytes per element / the N-thread triad (the fraction of the machine's bandwidth\n"
      "the N-thread pass uses); triad = GB/s on 1 and on N threads (medians).\n");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<long long> sizes = {1000, 10000, 100000, 1000000};
  double seconds = 0.5;
  int reps = 5;
  bool bullet = true, variants = true, f64 = true, f32 = true, huge = true, check = false;
  int threads = 0;
  const char* csv_path = nullptr;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) {
      sizes = {1000, 10000}, seconds = 0.1, reps = 3;
    } else if (!std::strcmp(argv[i], "--no-bullet")) {
      bullet = false;
    } else if (!std::strcmp(argv[i], "--csv") && i + 1 < argc) {
      csv_path = argv[++i];
    } else if (!std::strcmp(argv[i], "--atoms") && i + 1 < argc) {
      sizes = {std::atoll(argv[++i])};
    } else if (!std::strcmp(argv[i], "--precision") && i + 1 < argc) {
      const char* p = argv[++i];
      f64 = !std::strcmp(p, "f64") || !std::strcmp(p, "both");
      f32 = !std::strcmp(p, "f32") || !std::strcmp(p, "both");
      if (!f64 && !f32) {
        std::fprintf(stderr, "--precision: expected f32, f64 or both, got '%s'\n", p);
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--no-huge-pages")) {
      huge = false;
    } else if (!std::strcmp(argv[i], "--main-only")) {
      variants = false, bullet = false;
    } else if (!std::strcmp(argv[i], "--energy-check")) {
      check = true;
    } else if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) {
      threads = std::atoi(argv[++i]);
      if (threads < 1 || threads > 64) {
        std::fprintf(stderr, "--threads: expected 1..64, got '%s'\n", argv[i]);
        return 2;
      }
    } else {
      std::fprintf(stderr,
                   "usage: %s [--quick] [--no-bullet] [--main-only] [--no-huge-pages] [--energy-check] "
                   "[--precision f32|f64|both] [--atoms N] [--threads N] [--csv FILE]\n",
                   argv[0]);
      return 2;
    }
  }

  if (threads > 0) return RunThreads(sizes, threads, seconds, reps, f64, f32, huge, check);
  double triad = 0;
  {
    std::vector<double> a(size_t{40} << 20, 0.0), b(size_t{40} << 20, 1.0), c(size_t{40} << 20, 2.0);
    triad = Triad(a, b, c, 7);
  }
  std::printf(
      "STREAM triad (one core, 3 x 320 MiB, thread CPU time): %.2f GB/s (median of 7); each repetition\n"
      "below is paired with its own triad (3 x 128 MiB, median of 3) taken just before it\n",
      triad / 1e9);
  std::printf(
      "full model, symplectic Euler, eq. 4.6 filter on, energy check %s, one core; slabs renumbered by "
      "`idms-sim reorder`\n\n",
      check ? "on (formed in the pass)" : "off");
  std::printf("%9s %9s | %10s %6s %5s | %10s %6s %5s %6s | %10s %10s | %10s %7s\n", "atoms", "elements", "f64 el/s",
              "B/el", "bound", "f32 el/s", "B/el", "bound", "triad", "f32 as-gen", "f32 gener.", "bullet", "f32/blt");
  std::FILE* csv = csv_path ? std::fopen(csv_path, "w") : nullptr;
  if (csv) {
    std::fprintf(csv,
                 "atoms,elements,double_el_per_s,double_bytes_per_el,double_bound_ratio,float_el_per_s,"
                 "float_bytes_per_el,float_bound_ratio,float_as_generated_el_per_s,float_general_el_per_s,"
                 "double_general_el_per_s,bullet_el_per_s,triad_bytes_per_s,float_paired_triad_bytes_per_s,"
                 "double_huge_mib,float_huge_mib\n");
  }
  std::string huge_note;
  for (long long n : sizes) {
    const ThroughputVariant main_variant{.huge_pages = huge, .energy_check = check};
    const ThroughputResult d = f64 ? RunThroughputDouble(n, seconds, reps, main_variant) : ThroughputResult{};
    const ThroughputResult f = f32 ? RunThroughputFloat(n, seconds, reps, main_variant) : ThroughputResult{};
    // --main-only: the fused pass on the renumbered slab only (the other columns print 0).
    const ThroughputResult f_gen = variants && f32
                                       ? RunThroughputFloat(n, seconds, reps, {.reorder = false, .huge_pages = huge})
                                       : ThroughputResult{};
    const ThroughputResult f_general =
        variants && f32 ? RunThroughputFloat(n, seconds, reps, {.reorder = true, .fused = false, .huge_pages = huge})
                        : ThroughputResult{};
    const ThroughputResult d_general =
        variants && f64 ? RunThroughputDouble(n, seconds, reps, {.reorder = true, .fused = false, .huge_pages = huge})
                        : ThroughputResult{};
    int64_t links = 0;
    const double b = bullet ? RunBulletSoftBody(n, seconds, reps, &links) : 0;
    const double d_ratio = d.bound_ratio, f_ratio = f.bound_ratio;
    std::printf("%9lld %9lld | %10.3e %6.1f %4.0f%% | %10.3e %6.1f %4.0f%% %6.1f | %10.3e %10.3e | ",
                static_cast<long long>(f64 ? d.atoms : f.atoms), static_cast<long long>(f64 ? d.elements : f.elements),
                d.elem_updates_per_s, d.bytes_per_elem, 100 * d_ratio, f.elem_updates_per_s, f.bytes_per_elem,
                100 * f_ratio, f.triad_bytes_per_s / 1e9, f_gen.elem_updates_per_s, f_general.elem_updates_per_s);
    if (b > 0) {
      std::printf("%10.3e %6.1fx\n", b, f.elem_updates_per_s / b);
    } else {
      std::printf("%10s %7s\n", "n/a", "n/a");
    }
    if (csv) {
      std::fprintf(csv, "%lld,%lld,%.6g,%.4g,%.4f,%.6g,%.4g,%.4f,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.1f,%.1f\n",
                   static_cast<long long>(f64 ? d.atoms : f.atoms),
                   static_cast<long long>(f64 ? d.elements : f.elements), d.elem_updates_per_s, d.bytes_per_elem,
                   d_ratio, f.elem_updates_per_s, f.bytes_per_elem, f_ratio, f_gen.elem_updates_per_s,
                   f_general.elem_updates_per_s, d_general.elem_updates_per_s, b, triad, f.triad_bytes_per_s,
                   d.huge_mib, f.huge_mib);
    }
    if (d.timed_warnings + f.timed_warnings > 0) {
      std::printf("  (warnings while timed: f64 %lld, f32 %lld: some steps took the general path)\n",
                  static_cast<long long>(d.timed_warnings), static_cast<long long>(f.timed_warnings));
    }
    std::fflush(stdout);
    char line[128];
    std::snprintf(line, sizeof line, " %lld atoms: f64 %.0f MiB, f32 %.0f MiB;", n, d.huge_mib, f.huge_mib);
    huge_note += line;
  }
  if (csv) std::fclose(csv);
  std::printf(
      "\nel/s = element updates per second (thread CPU time, median); B/el = bytes the fused pass streams per\n"
      "element and step, counted from its layout; bound = median over repetitions of el/s / (triad bytes/s / B/el),\n"
      "each repetition against the triad taken just before it; triad = the f32 run's median paired triad, GB/s.\n"
      "f32 as-gen = the slab in generator order (element arrays read through an index); f32 gener. = the general\n"
      "path on the renumbered slab (StepOptions as above, the fused pass switched off).\n"
      "The pass's arrays on 2 MiB pages (AdviseHugePages%s):%s\n",
      huge ? "" : ", off: --no-huge-pages", huge_note.c_str());
  return 0;
}
