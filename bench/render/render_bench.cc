// idms-render-bench: ms per frame at 1280x720 and 1920x1080 for ~10^4 and ~10^5 triangles, and
// PNG encode ms (ours: zlib 1 + one filter; libpng's defaults for comparison). Medians of
// --reps runs after warm-up. Prints figures; never fails on time. render_bench.sh runs it and
// measures the server's screenshot endpoint end to end.
#include <png.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "idms/render/png.h"
#include "idms/render/render.h"
#include "idms/render/source.h"
#include "idms/sim/generate.h"
#include "idms/sim/model.h"

namespace {

using namespace idms;
using Clock = std::chrono::steady_clock;

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

template <class F>
double MedianMs(int reps, F f) {
  for (int i = 0; i < 3; ++i) f();
  std::vector<double> ms;
  for (int i = 0; i < reps; ++i) {
    const auto t0 = Clock::now();
    f();
    ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  return Median(ms);
}

// A slab of about `triangles` triangles with a smooth bump, so that shading varies across it.
Model BumpySlab(int triangles) {
  SlabOptions o;
  o.rows = o.cols = static_cast<int32_t>(std::sqrt(triangles / 2.0));
  o.name = "bench" + std::to_string(triangles);
  Model m = GenerateSlab(o);
  const double cx = o.cols / 2.0, cy = o.rows * 0.866 / 2.0, w = o.cols / 4.0;
  for (int32_t a : m.external_atoms) {
    double* p = &m.atom_pos_eq[3 * static_cast<size_t>(a)];
    p[2] += 0.15 * o.cols * std::exp(-((p[0] - cx) * (p[0] - cx) + (p[1] - cy) * (p[1] - cy)) / (w * w));
  }
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"idms-render-bench: render and PNG figures (medians)"};
  int reps = 30;
  app.add_option("--reps", reps, "Timed runs per figure")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  render::Renderer renderer;
  if (!renderer.ok()) return std::fprintf(stderr, "%s\n", renderer.error().c_str()), 2;
  std::printf("idms-render-bench: medians of %d runs; LP_NUM_THREADS=%s\n", reps,
              std::getenv("LP_NUM_THREADS") ? std::getenv("LP_NUM_THREADS") : "(llvmpipe default)");
  std::printf("%-10s %-10s %10s %10s\n", "triangles", "size", "render_ms", "png_ms");
  render::Image image;
  std::string error, png;
  for (int triangles : {10000, 20000, 100000}) {
    render::ViewerState state;
    if (!render::LoadRestState(BumpySlab(triangles), &state, &error))
      return std::fprintf(stderr, "%s\n", error.c_str()), 2;
    for (auto [w, h] : {std::pair{1280, 720}, std::pair{1920, 1080}}) {
      render::RenderOptions o;
      o.width = w, o.height = h;
      const double render_ms = MedianMs(reps, [&] { renderer.Render(state.View(), o, &image, &error); });
      const double png_ms = MedianMs(reps, [&] { render::EncodePng(image, &png, &error); });
      std::printf("%-10d %4dx%-5d %10.2f %10.2f   (%zu KiB png)\n", state.mirror.num_triangles(), w, h, render_ms,
                  png_ms, png.size() / 1024);
    }
  }
  // libpng's defaults (adaptive filters, zlib 6) on the last 1920x1080 image, for comparison.
  size_t default_bytes = 0;
  const double default_ms = MedianMs(std::max(5, reps / 3), [&] {
    png_image pi{};
    pi.version = PNG_IMAGE_VERSION;
    pi.width = static_cast<png_uint_32>(image.width);
    pi.height = static_cast<png_uint_32>(image.height);
    pi.format = PNG_FORMAT_RGBA;
    png_alloc_size_t size = 0;
    png_image_write_get_memory_size(pi, size, 0, image.rgba.data(), 0, nullptr);
    std::vector<uint8_t> buffer(size);
    png_image_write_to_memory(&pi, buffer.data(), &size, 0, image.rgba.data(), 0, nullptr);
    default_bytes = size;
  });
  std::printf("png with libpng defaults (1920x1080): %.2f ms, %zu KiB\n", default_ms, default_bytes / 1024);
  return 0;
}
