// idms_render: draws a surface (what a MeshMirror holds), the tool marker and the force arrow
// with OSMesa (llvmpipe: no display, no GPU) into an RGBA image. One OSMesa context per Renderer,
// made once and reused for every image: a server that renders often pays the set-up once.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "idms/render/params.h"

namespace idms::render {

// An image, rows top first, 4 bytes per pixel (R, G, B, A).
struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // (height x width x 4)
  const uint8_t* Pixel(int x, int y) const { return &rgba[(static_cast<size_t>(y) * width + x) * 4]; }
};

struct RenderOptions {
  int width = 1280, height = 720;  // pixels, each within [kMinSize, kMaxSize]
  Camera camera;
  bool wireframe = false;   // the triangles' edges instead of the shaded surface
  bool show_tool = false;   // the tool sphere at the device position, with its radius
  bool show_force = false;  // the device force as an arrow from the tool
};

// What to draw: a view of the mirror's arrays (not copied) and the device's last sample.
struct SceneView {
  std::span<const float> positions;    // (num_vertices x 3), model units
  std::span<const int32_t> triangles;  // (num_triangles x 3), vertex ids, counter-clockwise from outside
  bool has_tool = false;
  std::array<double, 3> tool_pos{0, 0, 0};  // model frame, model units
  double tool_radius = 0;                   // model units; 0 = unknown (drawn as 5 % of the view)
  std::array<double, 3> force{0, 0, 0};     // force on the device, model frame, force units
};

// Colours, as the tests expect them (linear 0..1).
inline constexpr std::array<float, 3> kBackground{0.93f, 0.94f, 0.96f};
inline constexpr std::array<float, 3> kTissue{0.86f, 0.50f, 0.45f};      // front faces
inline constexpr std::array<float, 3> kTissueBack{0.45f, 0.45f, 0.58f};  // back faces
inline constexpr std::array<float, 3> kToolColour{0.20f, 0.45f, 0.95f};
inline constexpr std::array<float, 3> kForceColour{0.95f, 0.80f, 0.10f};
inline constexpr std::array<float, 3> kWireColour{0.15f, 0.20f, 0.30f};
// Light: directional, in eye coordinates, from the viewer's upper left.
inline constexpr std::array<float, 3> kLightDirEye{-0.45f, 0.55f, 0.70f};
// The force arrow is this many tool radii long per unit of force, at most kMaxArrowRadii radii.
inline constexpr double kArrowRadiiPerForce = 1.0;
inline constexpr double kMaxArrowRadii = 4.0;

// Owned by one thread (OSMesa's current context is per thread). Not copyable.
class Renderer {
 public:
  Renderer();
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // False when OSMesa could not make a context; then Render fails with the reason.
  bool ok() const { return impl_ != nullptr && error_.empty(); }
  const std::string& error() const { return error_; }

  // Draws `scene` into *out (resized to the options' size; reuse it to avoid allocation).
  // Fails on an empty surface, a vertex id out of range, or a size out of range.
  bool Render(const SceneView& scene, const RenderOptions& options, Image* out, std::string* error);

  // Where a model-frame point landed in the last image, in pixels (x right, y down); false when
  // behind the camera.
  bool Project(const std::array<double, 3>& p, double* x, double* y) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string error_;
};

// The automatic camera for a surface: from above and in front (z up), far enough back that its
// bounding box is in view, and the boxes of `spheres` (x, y, z, radius: the tool, the arrow's tip).
Camera AutoCamera(std::span<const float> positions, double aspect, std::span<const std::array<double, 4>> spheres = {});
// The camera Render uses for `scene` with `options` (the automatic one, or the options').
Camera CameraFor(const SceneView& scene, const RenderOptions& options);

}  // namespace idms::render
