// The renderer against expectations that fail if nothing or the wrong mesh were drawn: coverage
// by the lit surface, lit and shadowed colours, front and back, the dent under the tool after a
// real palpation, the tool marker where the device was, the force arrow, and determinism.
#include "idms/render/render.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <numbers>

#include "idms/render/display.h"
#include "idms/render/png.h"
#include "idms/render/source.h"
#include "recording_fixture.h"

namespace idms::render {
namespace {

const std::string kModels = std::string(IDMS_SOURCE_DIR) + "/models/";

bool IsBackground(const uint8_t* p) {
  for (int c = 0; c < 3; ++c) {
    if (std::abs(p[c] - std::lround(kBackground[c] * 255)) > 2) return false;
  }
  return true;
}

double Luma(const uint8_t* p) { return 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]; }

struct Coverage {
  int64_t covered = 0;
  int min_x = 1 << 30, max_x = -1, min_y = 1 << 30, max_y = -1;
};

Coverage Cover(const Image& image) {
  Coverage c;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      if (IsBackground(image.Pixel(x, y))) continue;
      ++c.covered;
      c.min_x = std::min(c.min_x, x), c.max_x = std::max(c.max_x, x);
      c.min_y = std::min(c.min_y, y), c.max_y = std::max(c.max_y, y);
    }
  }
  return c;
}

// Mean luma of the surface's pixels in columns [x0, x1).
double MeanLuma(const Image& image, int x0, int x1) {
  double sum = 0;
  int64_t n = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = x0; x < x1; ++x) {
      if (!IsBackground(image.Pixel(x, y))) sum += Luma(image.Pixel(x, y)), ++n;
    }
  }
  return n > 0 ? sum / static_cast<double>(n) : -1;
}

TEST(Params, SizeCameraSeconds) {
  int w = 0, h = 0;
  std::string error;
  EXPECT_TRUE(ParseSize("1280x720", &w, &h, &error));
  EXPECT_EQ(w, 1280);
  EXPECT_EQ(h, 720);
  for (const char* bad : {"", "1280", "x720", "1280x", "12x720", "99999x10", "4096x4096", "-5x100", "1280x720x3",
                          "+100x100", "100 x100"}) {
    EXPECT_FALSE(ParseSize(bad, &w, &h, &error)) << bad;
  }
  EXPECT_NE(error.find("expected"), std::string::npos);
  Camera c;
  EXPECT_TRUE(ParseCamera("1,2,3:0,0,-1.5", &c, &error));
  EXPECT_FALSE(c.automatic);
  EXPECT_EQ(c.eye[1], 2);
  EXPECT_EQ(c.target[2], -1.5);
  EXPECT_TRUE(ParseCamera("auto", &c, &error));
  EXPECT_TRUE(c.automatic);
  for (const char* bad : {"", "1,2:3,4,5", "1,2,3", "1,2,3:4,5", "1,2,3:1,2,3", "nan,0,0:1,1,1", "1,2,3:4,5,6,7"}) {
    EXPECT_FALSE(ParseCamera(bad, &c, &error)) << bad;
  }
  double s = 0;
  EXPECT_TRUE(ParseSeconds("1.25", &s, &error));
  EXPECT_EQ(s, 1.25);
  for (const char* bad : {"", "-1", "inf", "nan", "1s", "abc"}) EXPECT_FALSE(ParseSeconds(bad, &s, &error)) << bad;
}

class RenderTest : public ::testing::Test {
 protected:
  Image Draw(const ViewerState& state, const RenderOptions& options) {
    Image image;
    std::string error;
    EXPECT_TRUE(renderer_.ok()) << renderer_.error();
    EXPECT_TRUE(renderer_.Render(state.View(), options, &image, &error)) << error;
    return image;
  }
  Renderer renderer_;
};

TEST_F(RenderTest, TheLitSurfaceCoversTheFramedImageInTissueColour) {
  ViewerState cap;
  std::string error;
  ASSERT_TRUE(LoadRestState(kModels + "sphere_cap", &cap, &error)) << error;
  RenderOptions o;
  o.width = 640, o.height = 480;
  o.legend = false;
  const Image image = Draw(cap, o);
  const Coverage c = Cover(image);
  // The automatic camera frames the cap: a good part of the image, centred, never cut off.
  const double fraction = static_cast<double>(c.covered) / (o.width * o.height);
  EXPECT_GT(fraction, 0.15);
  EXPECT_LT(fraction, 0.9);
  EXPECT_GT(c.min_x, 0);
  EXPECT_LT(c.max_x, o.width - 1);
  EXPECT_GT(c.min_y, 0);
  EXPECT_LT(c.max_y, o.height - 1);
  EXPECT_NEAR((c.min_x + c.max_x) / 2.0, o.width / 2.0, o.width * 0.1);
  // The brightest surface pixel is the colour map's first entry (no displacement at rest), a pale
  // peach: red over green over blue.
  const uint8_t* best = nullptr;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      if (!IsBackground(image.Pixel(x, y)) && (best == nullptr || Luma(image.Pixel(x, y)) > Luma(best)))
        best = image.Pixel(x, y);
    }
  }
  ASSERT_NE(best, nullptr);
  EXPECT_GT(best[0], 180);
  EXPECT_GE(best[0], best[1]);
  EXPECT_GE(best[1], best[2]);
  EXPECT_GT(best[0], best[2] + 15);
  // Nothing to draw is an error, not a blank image.
  ViewerState empty;
  Image blank;
  EXPECT_FALSE(renderer_.Render(empty.View(), o, &blank, &error));
}

TEST_F(RenderTest, TheSideFacingTheLightIsBrighterAndTheBackSideHasItsOwnColour) {
  ViewerState cap;
  std::string error;
  ASSERT_TRUE(LoadRestState(kModels + "sphere_cap", &cap, &error)) << error;
  RenderOptions o;
  o.width = 640, o.height = 480;
  o.legend = false;
  const Image image = Draw(cap, o);
  const Coverage c = Cover(image);
  // The key light comes from the left (display.json), grazing: the cap's left side is lit, its right in shade.
  const int quarter = (c.max_x - c.min_x) / 4;
  const double left = MeanLuma(image, c.min_x, c.min_x + quarter);
  const double right = MeanLuma(image, c.max_x - quarter, c.max_x + 1);
  EXPECT_GT(left, right + 25) << "left " << left << ", right " << right;
  // Seen from below, the flat hex fragment shows its back: the back colour, blue over red.
  ViewerState hex;
  ASSERT_TRUE(LoadRestState(kModels + "hex_4x5_home", &hex, &error)) << error;
  RenderOptions below = o;
  ASSERT_TRUE(ParseCamera("2,1.7,-8:2,1.7,0", &below.camera, &error));
  const Image back = Draw(hex, below);
  const uint8_t* centre = back.Pixel(o.width / 2, o.height / 2);
  EXPECT_GT(centre[2], centre[0]) << int(centre[0]) << "," << int(centre[1]) << "," << int(centre[2]);
  RenderOptions above = o;
  ASSERT_TRUE(ParseCamera("2,1.7,8:2,1.7,0", &above.camera, &error));
  const Image front = Draw(hex, above);
  const uint8_t* top = front.Pixel(o.width / 2, o.height / 2);
  EXPECT_GT(top[0], top[2] + 25) << int(top[0]) << "," << int(top[1]) << "," << int(top[2]);
  // Wireframe: edges, mostly background in between.
  RenderOptions wire = above;
  wire.wireframe = true;
  EXPECT_LT(Cover(Draw(hex, wire)).covered, Cover(front).covered / 3);
}

class RecordingRenderTest : public RenderTest {
 protected:
  void SetUp() override {
    test::RecordedSession& s = test::Session();
    ASSERT_EQ(s.error, "");
    ASSERT_GT(s.peak_force, 0.3) << "the palpation never pressed";
    std::string error;
    ASSERT_TRUE(player_.Open(s.recording, &error)) << error;
  }
  RecordingPlayer player_;
};

TEST_F(RecordingRenderTest, TheDentUnderTheToolAfterPalpation) {
  const test::RecordedSession& s = test::Session();
  std::string error;
  // The surface at rest (t = 0) and at the peak force, through one fixed camera from above.
  ASSERT_TRUE(player_.MoveTo(0, &error)) << error;
  RenderOptions o;
  o.width = 800, o.height = 600;
  o.legend = false;
  const std::vector<float> rest(player_.state().mirror.positions().begin(), player_.state().mirror.positions().end());
  o.camera = AutoCamera(rest, 800.0 / 600);
  const Image at_rest = Draw(player_.state(), o);
  ASSERT_TRUE(player_.MoveTo(s.peak_force_t_s, &error)) << error;
  const Image pressed = Draw(player_.state(), o);
  ASSERT_TRUE(player_.state().has_sample);
  const double tx = player_.state().sample.tool_pos().x(), ty = player_.state().sample.tool_pos().y();
  // The mesh itself: the vertex nearest the tool went down.
  const auto pos = player_.state().mirror.positions();
  double nearest = 1e9, dz = 0;
  for (size_t i = 0; i < rest.size(); i += 3) {
    const double d = std::hypot(rest[i] - tx, rest[i + 1] - ty);
    if (d < nearest) nearest = d, dz = pos[i + 2] - rest[i + 2];
  }
  EXPECT_LT(dz, -0.05) << "no dent in the mirror";
  RecordProperty("dent_depth", std::to_string(dz));
  // The image, seen from above: pixels around the point under the tool changed (the shading of a
  // dent this shallow changes by a level or two).
  double px = 0, py = 0;
  ASSERT_TRUE(renderer_.Project({tx, ty, 0}, &px, &py));
  int64_t changed = 0;
  const int r = 60;
  for (int y = std::max(0, int(py) - r); y < std::min(o.height, int(py) + r); ++y) {
    for (int x = std::max(0, int(px) - r); x < std::min(o.width, int(px) + r); ++x)
      changed += std::memcmp(pressed.Pixel(x, y), at_rest.Pixel(x, y), 3) != 0;
  }
  EXPECT_GT(changed, 100) << "pixels that changed around (" << px << ", " << py << ")";
  // Seen edge on (the eye in the surface's plane), the flat fragment at rest is a line of nothing;
  // pressed, the dent shows below the horizon, under the tool.
  RenderOptions edge = o;
  edge.camera.automatic = false;
  edge.camera.eye = {tx, ty - 4, 0};
  edge.camera.target = {tx, ty, 0};
  const Image edge_rest = [&] {
    RecordingPlayer rest_player;
    EXPECT_TRUE(rest_player.Open(s.recording, &error) && rest_player.MoveTo(0, &error)) << error;
    return Draw(rest_player.state(), edge);
  }();
  const Image edge_pressed = Draw(player_.state(), edge);
  ASSERT_TRUE(renderer_.Project({tx, ty, 0}, &px, &py));
  const Coverage c_rest = Cover(edge_rest), c_pressed = Cover(edge_pressed);
  EXPECT_LT(c_rest.covered, o.width * 2) << "at rest, edge on: at most a line";
  EXPECT_GT(c_pressed.covered, c_rest.covered + 500) << "the dent, edge on";
  EXPECT_GT(c_pressed.max_y, py + 10) << "the dent goes below the surface's plane";
  EXPECT_NEAR((c_pressed.min_x + c_pressed.max_x) / 2.0, px, o.width * 0.15) << "under the tool";
  // Kept for a look when this fails.
  std::string png;
  for (const auto& [name, image] : {std::pair{"rest", &at_rest}, std::pair{"pressed", &pressed},
                                    std::pair{"edge_rest", &edge_rest}, std::pair{"edge_pressed", &edge_pressed}}) {
    ASSERT_TRUE(EncodePng(*image, &png, &error));
    ASSERT_TRUE(WriteFile(s.dir + "/dent_" + name + ".png", png, &error)) << error;
  }
  // Rendering the rest state again changes nothing: the difference is the dent, not noise.
  ASSERT_TRUE(player_.MoveTo(0, &error)) << error;
  EXPECT_EQ(Draw(player_.state(), o).rgba, at_rest.rgba);
}

// The share of pixels that changed clearly (some channel by more than kClearChange levels: a
// change a person sees, not a level of shading) between two images of one size, in a disc of
// radius_px around (cx, cy), and over the whole image.
constexpr int kClearChange = 24;
struct Change {
  double region = 0, image = 0;
  double outside = 0;  // changed pixels outside the disc, as a share of the image
};
Change ClearChange(const Image& a, const Image& b, double cx, double cy, double radius_px) {
  int64_t in = 0, in_changed = 0, changed = 0, out_changed = 0;
  for (int y = 0; y < a.height; ++y) {
    for (int x = 0; x < a.width; ++x) {
      const uint8_t *p = a.Pixel(x, y), *q = b.Pixel(x, y);
      const bool clear = std::max({std::abs(p[0] - q[0]), std::abs(p[1] - q[1]), std::abs(p[2] - q[2])}) > kClearChange;
      changed += clear;
      if (std::hypot(x + 0.5 - cx, y + 0.5 - cy) > radius_px) {
        out_changed += clear;
        continue;
      }
      ++in;
      in_changed += clear;
    }
  }
  return {in > 0 ? static_cast<double>(in_changed) / static_cast<double>(in) : 0,
          static_cast<double>(changed) / (static_cast<double>(a.width) * a.height),
          static_cast<double>(out_changed) / (static_cast<double>(a.width) * a.height)};
}

// What issue 28 measured: the palpation before contact and at its deepest press, as a viewer sees
// them by default (the server's screenshot: tool and force shown), through one camera (the
// deepest press's automatic one). The contact region is the disc of the tool's radius around the
// surface point under the tool, projected. Before the dent was coloured, the light grazed and the
// tool was an outline, 1.5 % of that region changed clearly (the opaque tool covered it in both
// images) and 0.59 % of the image (the silhouette); now about 80 % and 5 %.
TEST_F(RecordingRenderTest, TheContactRegionChangesClearlyAtTheDeepestPress) {
  const test::RecordedSession& s = test::Session();
  ASSERT_GE(s.before_contact_t_s, 0) << "the palpation started in contact";
  std::string error;
  RenderOptions o;
  o.width = 1280, o.height = 720;
  o.show_tool = o.show_force = true;
  ASSERT_TRUE(player_.MoveTo(s.peak_force_t_s, &error)) << error;
  o.camera = CameraFor(player_.state().View(), o);
  const Image pressed = Draw(player_.state(), o);
  const std::vector<int32_t> contacts_pressed = renderer_.contacts();
  const std::array<double, 3> tool{player_.state().sample.tool_pos().x(), player_.state().sample.tool_pos().y(),
                                   player_.state().sample.tool_pos().z()};
  const double r = player_.state().tool_radius;
  ASSERT_TRUE(player_.MoveTo(s.before_contact_t_s, &error)) << error;
  const Image before = Draw(player_.state(), o);
  // Contact atoms are marked at the press, none before it.
  EXPECT_GE(contacts_pressed.size(), 1u);
  EXPECT_EQ(renderer_.contacts().size(), 0u);
  // The surface point under the tool (the flat fragment's plane is z = 0) and the tool's radius there, in pixels.
  double cx = 0, cy = 0, ex = 0, ey = 0;
  ASSERT_TRUE(renderer_.Project({tool[0], tool[1], 0}, &cx, &cy));
  ASSERT_TRUE(renderer_.Project({tool[0] + r, tool[1], 0}, &ex, &ey));
  const double radius_px = std::hypot(ex - cx, ey - cy);
  const Change c = ClearChange(before, pressed, cx, cy, radius_px);
  std::printf("contact region (%.0f px around %.0f, %.0f): %.1f %% of its pixels changed clearly; the image: %.2f %%\n",
              radius_px, cx, cy, 100 * c.region, 100 * c.image);
  RecordProperty("contact_region_changed_percent", std::to_string(100 * c.region));
  RecordProperty("image_changed_percent", std::to_string(100 * c.image));
  std::string png;
  for (const auto& [name, image] : {std::pair{"before_contact", &before}, std::pair{"deepest", &pressed}}) {
    ASSERT_TRUE(EncodePng(*image, &png, &error));
    ASSERT_TRUE(WriteFile(s.dir + "/glance_" + name + ".png", png, &error)) << error;
  }
  EXPECT_GT(c.region, 0.5) << "the dent must change at least half of the contact region clearly";
  EXPECT_GT(c.image, 0.02);
}

// Exaggerated ten times, the dent goes ten times deeper in the image (seen edge on), its colours
// and the legend's range unchanged.
TEST_F(RecordingRenderTest, TheDeformationScaleExaggeratesTheDentNotItsColours) {
  const test::RecordedSession& s = test::Session();
  std::string error;
  ASSERT_TRUE(player_.MoveTo(s.peak_force_t_s, &error)) << error;
  const ViewerState& state = player_.state();
  const double tx = state.sample.tool_pos().x(), ty = state.sample.tool_pos().y();
  RenderOptions o;
  o.width = 800, o.height = 600;
  o.legend = false;
  o.camera.automatic = false;
  o.camera.eye = {tx, ty - 6, 0};
  o.camera.target = {tx, ty, 0};
  const Image one = Draw(state, o);
  double px = 0, py = 0;
  ASSERT_TRUE(renderer_.Project({tx, ty, 0}, &px, &py));
  o.deformation_scale = 10;
  const Image ten = Draw(state, o);
  const double depth_one = Cover(one).max_y - py, depth_ten = Cover(ten).max_y - py;
  EXPECT_GT(depth_one, 1);
  EXPECT_GT(depth_ten, 5 * depth_one) << depth_one << " px at x1, " << depth_ten << " px at x10";
  // From above, the vertex under the tool has the same colour either way (only its place moved).
  RenderOptions above;
  above.width = 800, above.height = 600;
  above.legend = false;
  above.camera = AutoCamera(state.rest, 800.0 / 600);
  const Image a1 = Draw(state, above);
  above.deformation_scale = 10;
  const Image a10 = Draw(state, above);
  EXPECT_NE(a1.rgba, a10.rgba);
  // The legend says so.
  above.legend = true;
  const Image legend1 = Draw(state, [&] {
    RenderOptions l = above;
    l.deformation_scale = 1;
    return l;
  }());
  const Image legend10 = Draw(state, above);
  int64_t differ = 0;
  for (int y = 0; y < 300; ++y) {
    for (int x = above.width - 250; x < above.width; ++x)
      differ += std::memcmp(legend1.Pixel(x, y), legend10.Pixel(x, y), 3) != 0;
  }
  EXPECT_GT(differ, 20) << "the legend's corner does not name the scale";
  // A scene that declares its units (Scene.units) gets its legend in mm: the corner differs, the
  // surface does not.
  ViewerState& in_mm = const_cast<ViewerState&>(state);  // the player's own; put back below
  in_mm.mm_per_unit = 25.4;
  const Image mm = Draw(in_mm, above);
  in_mm.mm_per_unit = 0;
  int64_t corner = 0, elsewhere = 0;
  for (int y = 0; y < above.height; ++y) {
    for (int x = 0; x < above.width; ++x) {
      const bool differs = std::memcmp(mm.Pixel(x, y), legend10.Pixel(x, y), 3) != 0;
      (x >= above.width - 250 && y < 300 ? corner : elsewhere) += differs;
    }
  }
  EXPECT_GT(corner, 20) << "the legend does not say mm";
  EXPECT_EQ(elsewhere, 0);
}

// The tumour model coloured by stiffness differs from the plain slab where its inclusion is, and
// only there; the plain slab is one colour (its elements all have one k).
TEST_F(RenderTest, ColouredByStiffnessTheInclusionShows) {
  ViewerState plain, tumour;
  std::string error;
  ASSERT_TRUE(LoadRestState(kModels + "slab_40x40", &plain, &error)) << error;
  ASSERT_TRUE(LoadRestState(kModels + "slab_40x40_tumour", &tumour, &error)) << error;
  ASSERT_EQ(plain.stiffness.size(), tumour.stiffness.size());
  RenderOptions o;
  o.width = 800, o.height = 600;
  o.legend = false;
  o.colour_by = ColourBy::kStiffness;
  const Image a = Draw(plain, o);
  const Image b = Draw(tumour, o);
  // The inclusion's region: the vertices stiffer than the slab's k, projected; a disc around their centre.
  const auto [lo, hi] = std::minmax_element(tumour.stiffness.begin(), tumour.stiffness.end());
  ASSERT_GT(*hi, 2 * *lo) << "the tumour model has no stiffer region";
  double sx = 0, sy = 0, n = 0, reach = 0;
  std::vector<std::pair<double, double>> stiff;
  for (size_t v = 0; v < tumour.stiffness.size(); ++v) {
    if (tumour.stiffness[v] < 0.5 * (*lo + *hi)) continue;
    double x = 0, y = 0;
    ASSERT_TRUE(renderer_.Project({tumour.rest[3 * v], tumour.rest[3 * v + 1], tumour.rest[3 * v + 2]}, &x, &y));
    stiff.emplace_back(x, y);
    sx += x, sy += y, ++n;
  }
  ASSERT_GT(n, 3);
  sx /= n, sy /= n;
  for (const auto& [x, y] : stiff) reach = std::max(reach, std::hypot(x - sx, y - sy));
  const Change inside = ClearChange(a, b, sx, sy, 0.6 * reach);
  std::printf("inclusion (%.0f px around %.0f, %.0f): %.1f %% of its pixels differ clearly; the image: %.2f %%\n",
              reach, sx, sy, 100 * inside.region, 100 * inside.image);
  EXPECT_GT(inside.region, 0.8);
  // Away from it, nothing differs.
  EXPECT_LT(ClearChange(a, b, sx, sy, 1.6 * reach).outside, 0.0005);
  std::string png;
  ASSERT_TRUE(EncodePng(b, &png, &error));
  ASSERT_TRUE(WriteFile(test::TempDir("stiffness") + "/tumour.png", png, &error));
}

// Pixels of the tool's outline: within 12 levels of the colour of the tool's state, on the circle
// of its projected radius around its projected centre (the ring is drawn over everything).
int64_t RingPixels(const Image& image, const Srgb& colour, double cx, double cy, double radius_px) {
  int64_t n = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
      if (d < radius_px * 0.9 || d > radius_px * 1.15) continue;
      const uint8_t* p = image.Pixel(x, y);
      n += std::abs(p[0] - colour[0]) <= 12 && std::abs(p[1] - colour[1]) <= 12 && std::abs(p[2] - colour[2]) <= 12;
    }
  }
  return n;
}

TEST_F(RecordingRenderTest, TheToolIsAnOutlineWhereTheDeviceWasAndTheForceArrowShows) {
  const test::RecordedSession& s = test::Session();
  std::string error;
  ASSERT_TRUE(player_.MoveTo(s.peak_force_t_s, &error)) << error;
  const ViewerState& state = player_.state();
  ASSERT_TRUE(state.has_sample);
  ASSERT_TRUE(state.sample.contact());
  EXPECT_NEAR(state.tool_radius, 1.5, 1e-9);  // the recorded scene's
  RenderOptions o;
  o.width = 800, o.height = 600;
  o.show_tool = true;
  o.camera = CameraFor(state.View(), o);  // the same for the images without the tool
  const Image with_tool = Draw(state, o);
  const std::array<double, 3> c{state.sample.tool_pos().x(), state.sample.tool_pos().y(), state.sample.tool_pos().z()};
  // The tool's radius across the view (along the camera's right, square to its line of sight), in pixels.
  const std::array<double, 3> f{o.camera.target[0] - o.camera.eye[0], o.camera.target[1] - o.camera.eye[1], 0};
  const double fn = std::hypot(f[0], f[1]);
  double cx = 0, cy = 0, tx = 0, ty = 0;
  ASSERT_TRUE(renderer_.Project(c, &cx, &cy));
  ASSERT_TRUE(
      renderer_.Project({c[0] + state.tool_radius * f[1] / fn, c[1] - state.tool_radius * f[0] / fn, c[2]}, &tx, &ty));
  const double radius_px = std::hypot(tx - cx, ty - cy);
  // In contact: a ring of the contact colour around where the device was, most of its circumference.
  const int64_t ring = RingPixels(with_tool, TheDisplay().tool_contact, cx, cy, radius_px);
  EXPECT_GT(ring, 2 * 3.14 * radius_px) << "the tool's outline at (" << cx << ", " << cy << "), " << radius_px << " px";
  // Inside it the tissue shows through: the pixel under the tool's centre is nearly what it is
  // without the tool (the fill is display.json's fill_alpha).
  o.show_tool = false;
  const Image without = Draw(state, o);
  EXPECT_LT(RingPixels(without, TheDisplay().tool_contact, cx, cy, radius_px), ring / 10);
  const uint8_t *p = with_tool.Pixel(int(cx), int(cy)), *q = without.Pixel(int(cx), int(cy));
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(p[k], q[k], 255 * TheDisplay().tool_fill_alpha + 2) << k;
  // The force arrow: yellow pixels appear only with --show-force.
  auto yellow = [](const Image& image) {
    int64_t n = 0;
    for (size_t i = 0; i < image.rgba.size(); i += 4) {
      n += image.rgba[i] > 150 && image.rgba[i + 1] > 170 && image.rgba[i + 2] < 80;
    }
    return n;
  };
  o.show_tool = o.show_force = true;
  const Image arrow = Draw(state, o);
  EXPECT_GT(yellow(arrow), 50);
  EXPECT_EQ(yellow(with_tool), 0);
  // Friction's part (issue 30): a magenta arrow along the sample's tangential force, only when
  // the sample carries one.
  auto magenta = [](const Image& image) {
    int64_t n = 0;
    for (size_t i = 0; i < image.rgba.size(); i += 4) {
      n += image.rgba[i] > 120 && image.rgba[i + 1] < 80 && image.rgba[i + 2] > 110;
    }
    return n;
  };
  EXPECT_EQ(magenta(arrow), 0);
  SceneView sliding = state.View();
  sliding.friction_force = {0.8, 0, 0};
  Image with_friction;
  ASSERT_TRUE(renderer_.Render(sliding, o, &with_friction, &error)) << error;
  EXPECT_GT(magenta(with_friction), 50);
  // A slipping contact's ring is display.json's slip colour; a sticking one keeps the contact's.
  sliding.slip = true;
  Image slipping;
  ASSERT_TRUE(renderer_.Render(sliding, o, &slipping, &error)) << error;
  EXPECT_GT(RingPixels(slipping, TheDisplay().tool_slip, cx, cy, radius_px), ring / 2);
  EXPECT_LT(RingPixels(with_friction, TheDisplay().tool_slip, cx, cy, radius_px), ring / 10);
}

// A needle (issue 32): its shaft runs back from the tip against its axis, steel, red while it is
// in; a sphere's scene has none; turned the other way, the shaft is on the other side.
TEST_F(RecordingRenderTest, ANeedlesShaftIsDrawnAlongItsAxisInItsStatesColour) {
  const test::RecordedSession& s = test::Session();
  std::string error;
  ASSERT_TRUE(player_.MoveTo(s.peak_force_t_s, &error)) << error;
  SceneView needle = player_.state().View();
  needle.tool_radius = 0.25;
  needle.needle_length = 5;
  const double tilt = 30 * std::numbers::pi / 180;
  needle.needle_axis = {std::sin(tilt), 0, -std::cos(tilt)};
  needle.force = {0, 0, 0};
  RenderOptions o;
  o.width = 800, o.height = 600;
  o.show_tool = true;
  o.camera = CameraFor(needle, o);
  // Pixels in a 7 x 7 box around (x, y) that are the lit shaft's: steel (blue-grey, darker than
  // the background) or red, lit (the tissue is orange: red above blue too, but green with it).
  auto steel = [](const uint8_t* p) { return p[2] > p[0] + 12 && p[0] < 215; };
  auto red = [](const uint8_t* p) { return p[0] > p[1] + 70 && p[0] > p[2] + 70 && std::abs(p[1] - p[2]) < 25; };
  auto near = [](const Image& image, auto is, double x, double y) {
    int n = 0;
    for (int dy = -3; dy <= 3; ++dy) {
      for (int dx = -3; dx <= 3; ++dx) {
        const int px = int(x) + dx, py = int(y) + dy;
        if (px >= 0 && py >= 0 && px < image.width && py < image.height) n += is(image.Pixel(px, py));
      }
    }
    return n;
  };
  // Three quarters of the way up the shaft (above the tissue), towards the tail.
  auto along = [&](const SceneView& v, double d, double* x, double* y) {
    return renderer_.Project({v.tool_pos[0] - v.needle_axis[0] * d, v.tool_pos[1] - v.needle_axis[1] * d,
                              v.tool_pos[2] - v.needle_axis[2] * d},
                             x, y);
  };
  Image image;
  ASSERT_TRUE(renderer_.Render(needle, o, &image, &error)) << error;
  double x = 0, y = 0;
  ASSERT_TRUE(along(needle, 3.75, &x, &y));
  EXPECT_GT(near(image, steel, x, y), 3) << "at (" << x << ", " << y << ")";
  needle.needle_punctured = true;
  ASSERT_TRUE(renderer_.Render(needle, o, &image, &error)) << error;
  EXPECT_GT(near(image, red, x, y), 3);
  EXPECT_EQ(near(image, steel, x, y), 0);
  // Turned the other way about z: nothing where the shaft was.
  SceneView turned = needle;
  turned.needle_axis = {-std::sin(tilt), 0, -std::cos(tilt)};
  ASSERT_TRUE(renderer_.Render(turned, o, &image, &error)) << error;
  EXPECT_EQ(near(image, red, x, y), 0);
  double tx = 0, ty = 0;
  ASSERT_TRUE(along(turned, 3.75, &tx, &ty));
  EXPECT_GT(near(image, red, tx, ty), 3);
  // Not a needle: no shaft.
  SceneView sphere = needle;
  sphere.needle_length = 0;
  ASSERT_TRUE(renderer_.Render(sphere, o, &image, &error)) << error;
  EXPECT_EQ(near(image, red, x, y), 0);
}

// A needle's suture thread (issue 32): a line through its nodes in display.json's thread colour,
// over the surface, with its punctures as squares in theirs; a parted segment is not drawn, and a
// frame without a thread draws none.
TEST_F(RecordingRenderTest, ASutureThreadIsDrawnOverTheSurfaceWithItsPunctures) {
  const test::RecordedSession& s = test::Session();
  std::string error;
  ASSERT_TRUE(player_.MoveTo(s.peak_force_t_s, &error)) << error;
  SceneView view = player_.state().View();
  EXPECT_TRUE(view.suture_nodes.empty());  // the palpation's frames carry none
  view.has_tool = false;                   // its see-through disc would tint the thread under it
  // A thread across the middle of the surface, in 16 segments, 1 above it; two punctures on it.
  const std::array<double, 3> lo = {0.5, 1.0, 0.5}, hi = {3.5, 1.0, 0.5};
  std::vector<float> nodes, punctures = {1.25f, 1.0f, 0.5f, 2.75f, 1.0f, 0.5f};
  for (int i = 0; i <= 16; ++i) {
    for (int c = 0; c < 3; ++c) nodes.push_back(static_cast<float>(lo[c] + (hi[c] - lo[c]) * i / 16.0));
  }
  view.suture_nodes = nodes;
  view.suture_punctures = punctures;
  RenderOptions o;
  o.width = 800, o.height = 600;
  o.show_tool = true;
  o.camera = CameraFor(view, o);
  const Display& d = TheDisplay();
  auto is = [](const Srgb& c) {
    return [c](const uint8_t* p) {
      return std::abs(p[0] - c[0]) < 8 && std::abs(p[1] - c[1]) < 8 && std::abs(p[2] - c[2]) < 8;
    };
  };
  auto near = [](const Image& image, auto match, double x, double y) {
    int n = 0;
    for (int dy = -4; dy <= 4; ++dy) {
      for (int dx = -4; dx <= 4; ++dx) {
        const int px = int(x) + dx, py = int(y) + dy;
        if (px >= 0 && py >= 0 && px < image.width && py < image.height) n += match(image.Pixel(px, py));
      }
    }
    return n;
  };
  auto at = [&](double f, double* x, double* y) {
    return renderer_.Project({lo[0] + (hi[0] - lo[0]) * f, lo[1], lo[2]}, x, y);
  };
  Image image;
  ASSERT_TRUE(renderer_.Render(view, o, &image, &error)) << error;
  double x = 0, y = 0;
  // On the thread between the punctures (segment 9 of 16 holds f = 0.59).
  ASSERT_TRUE(at(0.59, &x, &y));
  EXPECT_GT(near(image, is(d.suture_thread), x, y), 3) << "at (" << x << ", " << y << ")";
  ASSERT_TRUE(renderer_.Project({1.25, 1.0, 0.5}, &x, &y));
  EXPECT_GT(near(image, is(d.suture_puncture), x, y), 10);
  // Parted at segment 9 (+ 1 = 10): nothing there, the rest still drawn.
  view.suture_broken = 10;
  ASSERT_TRUE(renderer_.Render(view, o, &image, &error)) << error;
  ASSERT_TRUE(at(0.59, &x, &y));
  EXPECT_EQ(near(image, is(d.suture_thread), x, y), 0);
  ASSERT_TRUE(at(0.2, &x, &y));
  EXPECT_GT(near(image, is(d.suture_thread), x, y), 3);
  // No thread: none drawn.
  view.suture_nodes = {};
  view.suture_punctures = {};
  ASSERT_TRUE(renderer_.Render(view, o, &image, &error)) << error;
  EXPECT_EQ(near(image, is(d.suture_thread), x, y), 0);
}

TEST_F(RecordingRenderTest, TheSameTimeRenderedTwiceIsTheSameImage) {
  const test::RecordedSession& s = test::Session();
  std::string error;
  RenderOptions o;
  o.show_tool = o.show_force = true;
  // Forward to t, then back to t through a seek: the same surface, the same pixels, the same PNG.
  const double t = s.peak_force_t_s;
  ASSERT_TRUE(player_.MoveTo(t, &error)) << error;
  const Image a = Draw(player_.state(), o);
  ASSERT_TRUE(player_.MoveTo(s.duration_s, &error)) << error;
  ASSERT_TRUE(player_.MoveTo(t, &error)) << error;
  const Image b = Draw(player_.state(), o);
  EXPECT_EQ(a.rgba, b.rgba);
  std::string png_a, png_b;
  ASSERT_TRUE(EncodePng(a, &png_a, &error));
  ASSERT_TRUE(EncodePng(b, &png_b, &error));
  EXPECT_EQ(png_a, png_b);
  // The PNG decodes back to the pixels.
  Image decoded;
  ASSERT_TRUE(DecodePng(png_a, &decoded, &error)) << error;
  EXPECT_EQ(decoded.rgba, a.rgba);
  // Times outside the recording are refused with a reason.
  EXPECT_FALSE(player_.MoveTo(s.duration_s + 5, &error));
  EXPECT_NE(error.find("outside the recording"), std::string::npos) << error;
}

}  // namespace
}  // namespace idms::render
