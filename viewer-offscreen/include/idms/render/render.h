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

// What the surface's colour says (protocol/display.json has the map and the range rules).
enum class ColourBy {
  kDisplacement,  // |p - p_rest| per vertex, range fixed per model (DisplacementRange); the default
  kStiffness,     // per-vertex stiffness (SceneView::stiffness; a model's, StiffnessPerVertex)
  kPlain,         // one tissue colour
};

inline constexpr double kMaxDeformationScale = 100;

struct RenderOptions {
  int width = 1280, height = 720;  // pixels, each within [kMinSize, kMaxSize]
  Camera camera;
  bool wireframe = false;   // the triangles' edges instead of the shaded surface
  bool show_tool = false;   // the tool at the device position, with its radius (outlined, see-through)
  bool show_force = false;  // the device force as an arrow from the tool (and its friction part as a second one)
  ColourBy colour_by = ColourBy::kDisplacement;
  // Drawn position = rest + scale (p - rest): exaggerates the deformation; colours, contacts and
  // the tool stay true. In (0, kMaxDeformationScale].
  double deformation_scale = 1;
  bool legend = true;         // the colour bar, its ticks and unit (not below 400x300 pixels)
  bool show_contacts = true;  // the surface vertices in contact, while the device reports contact
};

// What to draw: a view of the mirror's arrays (not copied) and the device's last sample.
struct SceneView {
  std::span<const float> positions;    // (num_vertices x 3), model units
  std::span<const int32_t> triangles;  // (num_triangles x 3), vertex ids, counter-clockwise from outside
  bool has_tool = false;
  std::array<double, 3> tool_pos{0, 0, 0};  // model frame, model units
  double tool_radius = 0;                   // model units; 0 = unknown (drawn as 5 % of the view)
  // The scene's units (Scene.units), > 0 when declared: the legend then reads in mm (and N/mm).
  double mm_per_unit = 0;
  double newtons_per_force_unit = 0;
  std::array<double, 3> force{0, 0, 0};           // force on the device, model frame, force units
  std::array<double, 3> friction_force{0, 0, 0};  // its tangential (friction) part, the same frame and units
  bool contact = false, grasp = false;            // the device's last sample's flags
  bool slip = false;                              // its contact slipped (friction): the ring's slip colour
  // A needle (Tool.KIND_NEEDLE), when needle_length > 0: tool_pos is its tip, tool_radius the
  // tip's, and the shaft runs back from the tip against needle_axis (tail to tip, unit) for
  // needle_length; needle_punctured while it is in the tissue.
  double needle_length = 0;
  std::array<double, 3> needle_axis{0, 0, -1};
  bool needle_punctured = false;
  // Its suture thread (the mesh frame's SutureShape), when it has one: nodes from the eye (x, y,
  // z each), the points it passes through, the parted segment + 1 (0: whole).
  std::span<const float> suture_nodes;
  std::span<const float> suture_punctures;
  int32_t suture_broken = 0;
  // The surface at rest (num_vertices x 3), model units; empty: `positions` are taken as rest.
  std::span<const float> rest;
  double rest_time_s = 0;             // session time of `rest`; > 0: not the session's start (a late join)
  std::span<const double> stiffness;  // (num_vertices) for ColourBy::kStiffness; empty = unknown
};

// Colours (0..1, written to the image as they are). The surface's, the lights and the tool's are
// protocol/display.json's (display.h), shared with the browser.
inline constexpr std::array<float, 3> kBackground{0.93f, 0.94f, 0.96f};
inline constexpr std::array<float, 3> kForceColour{0.95f, 0.80f, 0.10f};
inline constexpr std::array<float, 3> kFrictionColour{0.80f, 0.15f, 0.75f};  // the force's tangential part
inline constexpr std::array<float, 3> kWireColour{0.15f, 0.20f, 0.30f};
// A needle's shaft: steel out of the tissue, red while it is in (its part under the surface shows
// through it, faint).
inline constexpr std::array<float, 3> kNeedleColour{0.45f, 0.50f, 0.58f};
inline constexpr std::array<float, 3> kNeedleInColour{0.80f, 0.18f, 0.16f};
// The shaft's radius: a third of the tip's, at least this many pixels.
inline constexpr double kNeedleMinPx = 1.5;
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
  // Fails on an empty surface, a vertex id out of range, a size out of range, rest or stiffness
  // of another size than the surface, colour by stiffness without it, or a scale out of range.
  bool Render(const SceneView& scene, const RenderOptions& options, Image* out, std::string* error);

  // Where a model-frame point landed in the last image, in pixels (x right, y down); false when
  // behind the camera.
  bool Project(const std::array<double, 3>& p, double* x, double* y) const;
  // The surface vertices marked in contact in the last image.
  const std::vector<int32_t>& contacts() const;

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
