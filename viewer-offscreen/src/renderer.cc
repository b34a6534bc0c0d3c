// The OSMesa renderer (llvmpipe), one context made in the constructor and reused. The surface:
// client-side vertex arrays, per-vertex normals recomputed from the drawn (deformed) surface every
// image (area-weighted), coloured through protocol/display.json's map and lit per pixel by its
// key and fill lights in a small GLSL program (the browser's surface shader does the same
// arithmetic); the contact vertices as squares; the tool as an outlined see-through disc over
// everything, so the contact patch keeps its colours; the force arrow; the legend in pixels.
#include <GL/osmesa.h>

#include <algorithm>
#include <cmath>

#include "idms/render/display.h"
#include "idms/render/render.h"
#include "legend_internal.h"

namespace idms::render {
namespace {

using Vec3 = std::array<double, 3>;

Vec3 Sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double Norm(const Vec3& a) { return std::sqrt(Dot(a, a)); }
Vec3 Scale(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
Vec3 Normalized(const Vec3& a) {
  const double n = Norm(a);
  return n > 0 ? Scale(a, 1 / n) : Vec3{0, 0, 1};
}

constexpr double kFovYDeg = 35;
constexpr double kPi = 3.14159265358979323846;

// Column-major 4x4 (OpenGL's layout).
using Mat4 = std::array<double, 16>;

Mat4 LookAt(const Vec3& eye, const Vec3& target) {
  const Vec3 f = Normalized(Sub(target, eye));
  // z is up in idms scenes; looking straight along z, y is.
  Vec3 up{0, 0, 1};
  if (Norm(Cross(f, up)) < 1e-6) up = {0, 1, 0};
  const Vec3 s = Normalized(Cross(f, up));
  const Vec3 u = Cross(s, f);
  return {s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0, -Dot(s, eye), -Dot(u, eye), Dot(f, eye), 1};
}

Mat4 Perspective(double fovy_deg, double aspect, double near_z, double far_z) {
  const double c = 1 / std::tan(fovy_deg * kPi / 360);
  Mat4 m{};
  m[0] = c / aspect;
  m[5] = c;
  m[10] = (far_z + near_z) / (near_z - far_z);
  m[11] = -1;
  m[14] = 2 * far_z * near_z / (near_z - far_z);
  return m;
}

std::array<double, 4> Mul(const Mat4& m, const std::array<double, 4>& v) {
  std::array<double, 4> r{};
  for (int i = 0; i < 4; ++i) r[i] = m[i] * v[0] + m[4 + i] * v[1] + m[8 + i] * v[2] + m[12 + i] * v[3];
  return r;
}

// A unit-length arrow (shaft and head along +z), built once.
struct Shape {
  std::vector<float> pos, normal;
  std::vector<uint32_t> tris;
  void Add(const Vec3& p, const Vec3& n) {
    for (int i = 0; i < 3; ++i) pos.push_back(static_cast<float>(p[i])), normal.push_back(static_cast<float>(n[i]));
  }
};

// A cylinder of radius 0.08 from z = 0 to 0.75 and a cone of radius 0.2 from 0.75 to 1.
Shape MakeArrow(int slices) {
  Shape s;
  const double r_shaft = 0.08, r_head = 0.2, z_head = 0.75;
  for (int j = 0; j <= slices; ++j) {
    const double phi = 2 * kPi * j / slices, c = std::cos(phi), sn = std::sin(phi);
    s.Add({r_shaft * c, r_shaft * sn, 0}, {c, sn, 0});
    s.Add({r_shaft * c, r_shaft * sn, z_head}, {c, sn, 0});
    const Vec3 cone_n = Normalized({c, sn, r_head / (1 - z_head)});
    s.Add({r_head * c, r_head * sn, z_head}, cone_n);
    s.Add({0, 0, 1}, cone_n);
  }
  for (int j = 0; j < slices; ++j) {
    const uint32_t a = static_cast<uint32_t>(4 * j), b = a + 4;
    s.tris.insert(s.tris.end(), {a, b, a + 1, a + 1, b, b + 1, a + 2, b + 2, a + 3, a + 3, b + 2, b + 3});
  }
  return s;
}

// A cylinder of radius 1 from z = 0 to 1, open at its ends (a needle's shaft).
Shape MakeCylinder(int slices) {
  Shape s;
  for (int j = 0; j <= slices; ++j) {
    const double phi = 2 * kPi * j / slices, c = std::cos(phi), sn = std::sin(phi);
    s.Add({c, sn, 0}, {c, sn, 0});
    s.Add({c, sn, 1}, {c, sn, 0});
  }
  for (int j = 0; j < slices; ++j) {
    const uint32_t a = static_cast<uint32_t>(2 * j), b = a + 2;
    s.tris.insert(s.tris.end(), {a, b, a + 1, a + 1, b, b + 1});
  }
  return s;
}

// The force arrow's length beyond the tool's surface, model units.
double ArrowLength(double tool_radius, double force) {
  return tool_radius * std::min(kArrowRadiiPerForce * force, kMaxArrowRadii);
}

void SetMaterial(GLenum face, const std::array<float, 3>& rgb, float specular) {
  const float diffuse[4] = {rgb[0], rgb[1], rgb[2], 1};
  const float spec[4] = {specular, specular, specular, 1};
  glMaterialfv(face, GL_AMBIENT_AND_DIFFUSE, diffuse);
  glMaterialfv(face, GL_SPECULAR, spec);
  glMaterialf(face, GL_SHININESS, 24);
}

void DrawShape(const Shape& s) {
  glVertexPointer(3, GL_FLOAT, 0, s.pos.data());
  glNormalPointer(GL_FLOAT, 0, s.normal.data());
  glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(s.tris.size()), GL_UNSIGNED_INT, s.tris.data());
}

void Colour(const Srgb& c, double alpha = 1) {
  glColor4f(c[0] / 255.0f, c[1] / 255.0f, c[2] / 255.0f, static_cast<float>(alpha));
}

// The surface's program: the value (a colour map entry / 255) and the normal interpolated, the
// colour looked up per pixel (the map's entries exactly, nearest texel), the key and fill lights
// per pixel (display.json's "light"): the same arithmetic as viewer-web's view/surface_material.js.
constexpr const char* kVertexShader = R"(#version 120
attribute float value;
varying float v_value;
varying vec3 v_normal;
void main() {
  v_value = value;
  v_normal = gl_Normal;
  gl_Position = gl_ModelViewProjectionMatrix * gl_Vertex;
}
)";
constexpr const char* kFragmentShader = R"(#version 120
uniform sampler1D colour_map;
uniform bool use_map;
uniform vec3 plain, back, key_towards, fill_towards;
uniform float ambient, key, fill;
varying float v_value;
varying vec3 v_normal;
void main() {
  vec3 n = normalize(v_normal);
  vec3 albedo = back;
  if (gl_FrontFacing) {
    float index = floor(clamp(v_value, 0.0, 1.0) * 255.0 + 0.5);
    albedo = use_map ? texture1D(colour_map, (index + 0.5) / 256.0).rgb : plain;
  } else {
    n = -n;
  }
  float light = ambient + key * max(dot(n, key_towards), 0.0) + fill * max(dot(n, fill_towards), 0.0);
  gl_FragColor = vec4(min(albedo * light, vec3(1.0)), 1.0);
}
)";

bool Compile(GLuint shader, const char* source, std::string* error) {
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok) return true;
  char log[1024] = {};
  glGetShaderInfoLog(shader, sizeof log, nullptr, log);
  return *error = std::string("surface shader: ") + log, false;
}

}  // namespace

struct Renderer::Impl {
  OSMesaContext ctx = nullptr;
  std::vector<float> drawn;    // (num_vertices x 3): rest + scale (p - rest), when scale != 1
  std::vector<float> normals;  // (num_vertices x 3), of the drawn surface
  std::vector<float> values;   // (num_vertices): the colour map entry / 255
  std::vector<int32_t> contacts;
  Shape arrow = MakeArrow(20);
  Shape cylinder = MakeCylinder(16);
  Mat4 view{}, proj{};
  int width = 0, height = 0;
  GLuint program = 0, colour_map = 0;
  GLint value_attr = -1;

  ~Impl() {
    if (ctx != nullptr) OSMesaDestroyContext(ctx);
  }

  // The surface's program and the map's texture, made once in the context (current).
  bool MakeProgram(std::string* error) {
    if (program != 0) return true;
    const GLuint vs = glCreateShader(GL_VERTEX_SHADER), fs = glCreateShader(GL_FRAGMENT_SHADER);
    if (!Compile(vs, kVertexShader, error) || !Compile(fs, kFragmentShader, error)) return false;
    program = glCreateProgram();
    glAttachShader(program, vs);
    glAttachShader(program, fs);
    glLinkProgram(program);
    GLint ok = 0;
    glGetProgramiv(program, GL_LINK_STATUS, &ok);
    if (!ok) return *error = "surface shader: link failed", false;
    value_attr = glGetAttribLocation(program, "value");
    // The map as a 256-texel 1D texture, looked up texel for texel.
    const Display& d = TheDisplay();
    std::vector<uint8_t> texels;
    for (const Srgb& c : d.map) texels.insert(texels.end(), c.begin(), c.end());
    glGenTextures(1, &colour_map);
    glBindTexture(GL_TEXTURE_1D, colour_map);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage1D(GL_TEXTURE_1D, 0, GL_RGB8, static_cast<GLsizei>(d.map.size()), 0, GL_RGB, GL_UNSIGNED_BYTE,
                 texels.data());
    glTexParameteri(GL_TEXTURE_1D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_1D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_1D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    // The lights and colours do not change either.
    glUseProgram(program);
    auto vec3 = [&](const char* name, double x, double y, double z) {
      glUniform3f(glGetUniformLocation(program, name), static_cast<float>(x), static_cast<float>(y),
                  static_cast<float>(z));
    };
    auto rgb = [&](const char* name, const Srgb& c) { vec3(name, c[0] / 255.0, c[1] / 255.0, c[2] / 255.0); };
    rgb("plain", d.plain);
    rgb("back", d.back);
    vec3("key_towards", d.key.towards[0], d.key.towards[1], d.key.towards[2]);
    vec3("fill_towards", d.fill.towards[0], d.fill.towards[1], d.fill.towards[2]);
    glUniform1f(glGetUniformLocation(program, "ambient"), static_cast<float>(d.ambient));
    glUniform1f(glGetUniformLocation(program, "key"), static_cast<float>(d.key.intensity));
    glUniform1f(glGetUniformLocation(program, "fill"), static_cast<float>(d.fill.intensity));
    glUniform1i(glGetUniformLocation(program, "colour_map"), 0);
    glUseProgram(0);
    return true;
  }

  // The positions drawn: the mirror's, or rest + scale (p - rest).
  std::span<const float> Drawn(const SceneView& scene, double scale) {
    if (scale == 1 || scene.rest.empty()) return scene.positions;
    drawn.resize(scene.positions.size());
    for (size_t i = 0; i < drawn.size(); ++i)
      drawn[i] = static_cast<float>(scene.rest[i] + scale * (static_cast<double>(scene.positions[i]) - scene.rest[i]));
    return drawn;
  }

  // Each vertex's colour map entry / 255 (ColourIndex, the browser's colourIndex): displacement
  // from rest over the model's range, or stiffness over its span.
  void ComputeValues(const SceneView& scene, ColourBy by, double* lo, double* hi) {
    const size_t nv = scene.positions.size() / 3;
    values.assign(nv, 0.0f);
    *lo = 0, *hi = 1;
    if (by == ColourBy::kDisplacement) {
      const std::span<const float> rest = scene.rest.empty() ? scene.positions : scene.rest;
      *hi = DisplacementRange(rest, scene.triangles);
      for (size_t v = 0; v < nv; ++v) {
        const double dx = static_cast<double>(scene.positions[3 * v]) - rest[3 * v];
        const double dy = static_cast<double>(scene.positions[3 * v + 1]) - rest[3 * v + 1];
        const double dz = static_cast<double>(scene.positions[3 * v + 2]) - rest[3 * v + 2];
        values[v] = static_cast<float>(ColourIndex(std::sqrt(dx * dx + dy * dy + dz * dz), 0, *hi)) / 255.0f;
      }
    } else if (by == ColourBy::kStiffness) {
      const auto [min_k, max_k] = std::minmax_element(scene.stiffness.begin(), scene.stiffness.end());
      *lo = *min_k, *hi = *max_k;
      for (size_t v = 0; v < nv; ++v)
        values[v] = static_cast<float>(ColourIndex(scene.stiffness[v], *lo, *hi)) / 255.0f;
    }
  }

  // Area-weighted vertex normals of the drawn surface: each triangle adds its unnormalized
  // normal to its corners.
  void ComputeNormals(std::span<const float> p, std::span<const int32_t> tris) {
    const size_t nv = p.size() / 3;
    normals.assign(nv * 3, 0.0f);
    const int32_t* t = tris.data();
    for (size_t i = 0; i + 2 < tris.size(); i += 3) {
      const float* a = p.data() + 3 * t[i];
      const float* b = p.data() + 3 * t[i + 1];
      const float* c = p.data() + 3 * t[i + 2];
      const float u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
      const float n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
      for (int k = 0; k < 3; ++k) {
        float* out = &normals[3 * static_cast<size_t>(t[i + k])];
        out[0] += n[0], out[1] += n[1], out[2] += n[2];
      }
    }
    for (size_t i = 0; i < nv; ++i) {
      float* n = &normals[3 * i];
      const float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      if (len > 0) {
        n[0] /= len, n[1] /= len, n[2] /= len;
      } else {
        n[0] = 0, n[1] = 0, n[2] = 1;
      }
    }
  }

  // The vertices in contact (display.json's "contact"): while the device reports contact, those
  // within (1 + tolerance) tool radii of its centre, at their true positions.
  void FindContacts(const SceneView& scene) {
    contacts.clear();
    if (!scene.has_tool || !scene.contact || !(scene.tool_radius > 0)) return;
    const double reach = scene.tool_radius * (1 + TheDisplay().contact_radius_tolerance);
    for (size_t v = 0; 3 * v + 2 < scene.positions.size(); ++v) {
      const double dx = scene.positions[3 * v] - scene.tool_pos[0], dy = scene.positions[3 * v + 1] - scene.tool_pos[1],
                   dz = scene.positions[3 * v + 2] - scene.tool_pos[2];
      if (dx * dx + dy * dy + dz * dz < reach * reach) contacts.push_back(static_cast<int32_t>(v));
    }
  }

  // Projection and view: near and far planes around everything drawn.
  void SetCamera(const SceneView& scene, const Camera& cam, const RenderOptions& o) {
    const double aspect = static_cast<double>(o.width) / o.height;
    Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (size_t i = 0; i + 2 < scene.positions.size(); i += 3) {
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], static_cast<double>(scene.positions[i + k]));
        hi[k] = std::max(hi[k], static_cast<double>(scene.positions[i + k]));
      }
    }
    if (scene.has_tool) {
      const double reach = scene.tool_radius * (1 + kMaxArrowRadii) + 1e-9;
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], scene.tool_pos[k] - reach);
        hi[k] = std::max(hi[k], scene.tool_pos[k] + reach);
      }
    }
    const Vec3 centre = Scale({lo[0] + hi[0], lo[1] + hi[1], lo[2] + hi[2]}, 0.5);
    const double radius = std::max(0.5 * Norm(Sub(hi, lo)), 1e-6);
    const double d = Norm(Sub(centre, cam.eye));
    const double far_z = d + radius * 1.01;
    const double near_z = std::max(d - radius * 1.01, far_z * 1e-4);
    view = LookAt(cam.eye, cam.target);
    proj = Perspective(kFovYDeg, aspect, near_z, far_z);
  }

  void DrawSurface(const SceneView& scene, std::span<const float> drawn_pos, ColourBy by, bool wireframe) {
    glVertexPointer(3, GL_FLOAT, 0, drawn_pos.data());
    glNormalPointer(GL_FLOAT, 0, normals.data());
    const GLsizei n = static_cast<GLsizei>(scene.triangles.size());
    if (wireframe) {
      glDisable(GL_LIGHTING);
      glColor3f(kWireColour[0], kWireColour[1], kWireColour[2]);
      glPolygonMode(GL_FRONT_AND_BACK, GL_LINE);
      glDrawElements(GL_TRIANGLES, n, GL_UNSIGNED_INT, scene.triangles.data());
      glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
      return;
    }
    glUseProgram(program);
    glUniform1i(glGetUniformLocation(program, "use_map"), by != ColourBy::kPlain);
    glBindTexture(GL_TEXTURE_1D, colour_map);
    glEnableVertexAttribArray(static_cast<GLuint>(value_attr));
    glVertexAttribPointer(static_cast<GLuint>(value_attr), 1, GL_FLOAT, GL_FALSE, 0, values.data());
    glDrawElements(GL_TRIANGLES, n, GL_UNSIGNED_INT, scene.triangles.data());
    glDisableVertexAttribArray(static_cast<GLuint>(value_attr));
    glUseProgram(0);
  }

  // The contact vertices: dark squares with light centres, over the surface.
  void DrawContacts(std::span<const float> drawn_pos) {
    if (contacts.empty()) return;
    const Display& d = TheDisplay();
    glDisable(GL_DEPTH_TEST);
    glVertexPointer(3, GL_FLOAT, 0, drawn_pos.data());
    const GLsizei n = static_cast<GLsizei>(contacts.size());
    glPointSize(static_cast<float>(d.contact_outer_px));
    Colour(d.contact_outer);
    glDrawElements(GL_POINTS, n, GL_UNSIGNED_INT, contacts.data());
    glPointSize(static_cast<float>(d.contact_inner_px));
    Colour(d.contact_inner);
    glDrawElements(GL_POINTS, n, GL_UNSIGNED_INT, contacts.data());
    glEnable(GL_DEPTH_TEST);
  }

  // The tool as the browser draws it: its silhouette (the eye's tangent cone meets the plane
  // through its centre square to the line of sight in a circle of radius r d / sqrt(d^2 - r^2))
  // filled at display.json's fill_alpha and outlined by a ring of outline_px pixels in the colour of
  // its state, over everything.
  void DrawTool(const SceneView& scene, const Camera& cam, double r, int image_height) {
    const Display& d = TheDisplay();
    const Vec3 c{scene.tool_pos[0], scene.tool_pos[1], scene.tool_pos[2]};
    const Vec3 to = Sub(c, cam.eye);
    const double dist = Norm(to);
    if (!(dist > r * 1.0001)) return;  // the eye inside the tool
    const Vec3 ahead = Scale(to, 1 / dist);
    const Vec3 u = Normalized(Cross(ahead, std::abs(ahead[2]) < 0.99 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}));
    const Vec3 v = Cross(u, ahead);
    const double outer = r * dist / std::sqrt(dist * dist - r * r);
    const double pixel = 2 * dist * std::tan(kFovYDeg * kPi / 360) / image_height;
    const double inner = std::max(0.0, outer - d.tool_outline_px * pixel);
    constexpr int kSegments = 96;
    auto point = [&](int i, double radius) {
      const double a = 2 * kPi * i / kSegments;
      const Vec3 p = {c[0] + (u[0] * std::cos(a) + v[0] * std::sin(a)) * radius,
                      c[1] + (u[1] * std::cos(a) + v[1] * std::sin(a)) * radius,
                      c[2] + (u[2] * std::cos(a) + v[2] * std::sin(a)) * radius};
      glVertex3d(p[0], p[1], p[2]);
    };
    const Srgb& colour = scene.grasp     ? d.tool_grasp
                         : scene.slip    ? d.tool_slip
                         : scene.contact ? d.tool_contact
                                         : d.tool_free;
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_LIGHTING);
    glEnable(GL_BLEND);
    glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ZERO, GL_ONE);  // the image stays opaque
    Colour(colour, d.tool_fill_alpha);
    glBegin(GL_TRIANGLE_FAN);
    glVertex3d(c[0], c[1], c[2]);
    for (int i = 0; i <= kSegments; ++i) point(i, inner);
    glEnd();
    Colour(colour);
    glBegin(GL_TRIANGLE_STRIP);
    for (int i = 0; i <= kSegments; ++i) point(i, inner), point(i, outer);
    glEnd();
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
  }

  // A needle's shaft from its tip back along its axis, lit, hidden where the tissue is in front of
  // it; then again over everything, faint, so that the part in the tissue shows through.
  void DrawNeedle(const SceneView& scene, const Camera& cam, double tip_radius, int image_height) {
    const Vec3 axis = Normalized({scene.needle_axis[0], scene.needle_axis[1], scene.needle_axis[2]});
    const Vec3 tip{scene.tool_pos[0], scene.tool_pos[1], scene.tool_pos[2]};
    const Vec3 z = Scale(axis, -1);  // tip to tail
    const Vec3 x = Normalized(Cross(std::abs(z[2]) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}, z));
    const Vec3 y = Cross(z, x);
    const double pixel = 2 * Norm(Sub(tip, cam.eye)) * std::tan(kFovYDeg * kPi / 360) / image_height;
    const double r = std::max(tip_radius / 3, kNeedleMinPx * pixel);
    const double len = scene.needle_length;
    const double m[16] = {x[0] * r,   x[1] * r,   x[2] * r,   0, y[0] * r, y[1] * r, y[2] * r, 0,
                          z[0] * len, z[1] * len, z[2] * len, 0, tip[0],   tip[1],   tip[2],   1};
    const std::array<float, 3>& colour = scene.needle_punctured ? kNeedleInColour : kNeedleColour;
    glPushMatrix();
    glMultMatrixd(m);
    glEnable(GL_LIGHTING);
    SetMaterial(GL_FRONT_AND_BACK, colour, 0.5f);
    DrawShape(cylinder);
    glDisable(GL_LIGHTING);
    glDisable(GL_DEPTH_TEST);
    glEnable(GL_BLEND);
    glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ZERO, GL_ONE);  // the image stays opaque
    glColor4f(colour[0], colour[1], colour[2], 0.35f);
    DrawShape(cylinder);
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glPopMatrix();
  }

  // A needle's suture thread over everything (the part in the tissue shows), as the browser draws
  // it: a line through its nodes (a parted segment left out), 2 pixels, and the points it passes
  // through as squares (display.json's "suture").
  void DrawSuture(const SceneView& scene) {
    const size_t n = scene.suture_nodes.size() / 3;
    if (n < 2) return;
    const Display& d = TheDisplay();
    glDisable(GL_DEPTH_TEST);
    glLineWidth(2);
    Colour(d.suture_thread);
    glBegin(GL_LINES);
    for (size_t i = 0; i + 1 < n; ++i) {
      if (static_cast<int32_t>(i) + 1 == scene.suture_broken) continue;
      glVertex3fv(&scene.suture_nodes[3 * i]);
      glVertex3fv(&scene.suture_nodes[3 * i + 3]);
    }
    glEnd();
    glLineWidth(1);
    glPointSize(static_cast<float>(d.suture_puncture_px));
    Colour(d.suture_puncture);
    glBegin(GL_POINTS);
    for (size_t j = 0; j + 2 < scene.suture_punctures.size(); j += 3) glVertex3fv(&scene.suture_punctures[j]);
    glEnd();
    glEnable(GL_DEPTH_TEST);
  }

  // The force arrow from the tool's surface, lit by one light from the viewer's upper left.
  // The device force, and its tangential (friction) part when there is one, each an arrow from
  // the tool's surface along it, the same length per unit of force.
  void DrawForce(const SceneView& scene, double r) {
    DrawArrow(scene, {scene.force[0], scene.force[1], scene.force[2]}, r, kForceColour);
    DrawArrow(scene, {scene.friction_force[0], scene.friction_force[1], scene.friction_force[2]}, r, kFrictionColour);
  }

  void DrawArrow(const SceneView& scene, const Vec3& f, double r, const std::array<float, 3>& colour) {
    const double magnitude = Norm(f);
    if (!(magnitude > 1e-9)) return;
    glEnable(GL_LIGHTING);
    const Vec3 z = Scale(f, 1 / magnitude);
    const Vec3 x = Normalized(Cross(std::abs(z[2]) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}, z));
    const Vec3 y = Cross(z, x);
    const double length = ArrowLength(r, magnitude);
    const Vec3 base = {scene.tool_pos[0] + z[0] * r, scene.tool_pos[1] + z[1] * r, scene.tool_pos[2] + z[2] * r};
    // The arrow's frame: x and y scaled with the radius (its thickness), z with its length.
    const double m[16] = {x[0] * r,      x[1] * r,      x[2] * r,      0, y[0] * r, y[1] * r, y[2] * r, 0,
                          z[0] * length, z[1] * length, z[2] * length, 0, base[0],  base[1],  base[2],  1};
    glPushMatrix();
    glMultMatrixd(m);
    SetMaterial(GL_FRONT_AND_BACK, colour, 0.3f);
    DrawShape(arrow);
    glPopMatrix();
    glDisable(GL_LIGHTING);
  }

  // The legend for what the colours say.
  void Legend(const SceneView& scene, const RenderOptions& o, double lo, double hi, Image* out) const {
    if (!o.legend || o.wireframe || o.colour_by == ColourBy::kPlain) return;
    LegendSpec spec;
    const Display& d = TheDisplay();
    spec.lo = lo, spec.hi = hi;
    // In mm (N/mm) when the scene declares its units, as the web viewer's legend.
    const bool mm = scene.mm_per_unit > 0, newtons = scene.newtons_per_force_unit > 0;
    if (o.colour_by == ColourBy::kDisplacement) {
      spec.title = "displacement";
      spec.unit = mm ? "mm" : d.length_unit;
      if (mm) spec.lo *= scene.mm_per_unit, spec.hi *= scene.mm_per_unit;
      spec.saturates = true;
      if (o.deformation_scale != 1) spec.notes.push_back("deformation \x02" + TickText(o.deformation_scale));
      if (scene.rest_time_s > d.rest_note_after_s)
        spec.notes.push_back("from t = " + TickText(scene.rest_time_s) + " s");
    } else {
      spec.title = "stiffness k";
      spec.unit = mm && newtons ? "N/mm" : d.stiffness_unit;
      if (mm && newtons) {
        const double k = scene.newtons_per_force_unit / scene.mm_per_unit;
        spec.lo *= k, spec.hi *= k;
      }
    }
    DrawLegend(spec, out);
  }
};

Renderer::Renderer() : impl_(std::make_unique<Impl>()) {
  impl_->ctx = OSMesaCreateContextExt(OSMESA_RGBA, 24, 0, 0, nullptr);
  if (impl_->ctx == nullptr) error_ = "OSMesa could not create a context (is libosmesa6 installed?)";
}

Renderer::~Renderer() = default;

bool Renderer::Render(const SceneView& scene, const RenderOptions& o, Image* out, std::string* error) {
  if (!ok()) return *error = error_, false;
  // The input, before any GL call.
  if (o.width < kMinSize || o.height < kMinSize || o.width > kMaxSize || o.height > kMaxSize ||
      static_cast<int64_t>(o.width) * o.height > kMaxPixels)
    return *error = "image size out of range", false;
  const size_t nv = scene.positions.size() / 3;
  if (nv == 0 || scene.triangles.empty() || scene.positions.size() % 3 != 0 || scene.triangles.size() % 3 != 0)
    return *error = "nothing to draw: the surface is empty", false;
  for (const int32_t v : scene.triangles) {
    if (v < 0 || static_cast<size_t>(v) >= nv) return *error = "a triangle names a vertex out of range", false;
  }
  for (const float p : scene.positions) {
    if (!std::isfinite(p)) return *error = "a vertex position is not finite", false;
  }
  if (!scene.rest.empty() && scene.rest.size() != scene.positions.size())
    return *error = "the rest surface has another number of vertices than the surface", false;
  if (o.colour_by == ColourBy::kStiffness && scene.stiffness.size() != nv)
    return *error = "colour by stiffness needs the model's elements (a model, not a recording or a live session)",
           false;
  if (!(o.deformation_scale > 0 && o.deformation_scale <= kMaxDeformationScale))
    return *error = "the deformation scale is out of (0, 100]", false;
  // Bind the image as the colour buffer (rows top first); the context stays the same.
  out->width = o.width;
  out->height = o.height;
  out->rgba.resize(static_cast<size_t>(o.width) * o.height * 4);
  if (!OSMesaMakeCurrent(impl_->ctx, out->rgba.data(), GL_UNSIGNED_BYTE, o.width, o.height))
    return *error = "OSMesaMakeCurrent failed", false;
  OSMesaPixelStore(OSMESA_Y_UP, 0);
  if (!impl_->MakeProgram(error)) return false;
  impl_->width = o.width;
  impl_->height = o.height;
  // What is drawn: the (exaggerated) surface, its normals and colours, the contacts.
  SceneView drawn = scene;
  drawn.positions = impl_->Drawn(scene, o.deformation_scale);
  impl_->ComputeNormals(drawn.positions, scene.triangles);
  double lo = 0, hi = 1;
  impl_->ComputeValues(scene, o.colour_by, &lo, &hi);
  impl_->contacts.clear();
  if (o.show_contacts && !o.wireframe) impl_->FindContacts(scene);
  const Camera cam = CameraFor(drawn, o);
  impl_->SetCamera(drawn, cam, o);
  // Fixed state: depth test; the surface's lighting is its program's, the arrow's one light's.
  glViewport(0, 0, o.width, o.height);
  glClearColor(kBackground[0], kBackground[1], kBackground[2], 1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glShadeModel(GL_SMOOTH);
  glDisable(GL_LIGHTING);
  glEnable(GL_LIGHT0);
  glEnable(GL_RESCALE_NORMAL);
  const float ambient[4] = {0.28f, 0.28f, 0.28f, 1}, diffuse[4] = {0.80f, 0.80f, 0.80f, 1},
              specular[4] = {0.6f, 0.6f, 0.6f, 1}, none[4] = {0, 0, 0, 1};
  const float arrow_light[4] = {-0.45f, 0.55f, 0.70f, 0};  // eye coordinates: the viewer's upper left
  glLightModelfv(GL_LIGHT_MODEL_AMBIENT, ambient);
  glLightfv(GL_LIGHT0, GL_AMBIENT, none);
  glLightfv(GL_LIGHT0, GL_DIFFUSE, diffuse);
  glLightfv(GL_LIGHT0, GL_SPECULAR, specular);
  glMatrixMode(GL_PROJECTION);
  glLoadMatrixd(impl_->proj.data());
  glMatrixMode(GL_MODELVIEW);
  glLoadIdentity();
  glLightfv(GL_LIGHT0, GL_POSITION, arrow_light);
  glLoadMatrixd(impl_->view.data());
  glEnableClientState(GL_VERTEX_ARRAY);
  glEnableClientState(GL_NORMAL_ARRAY);
  // The surface, the contacts, then the tool and the force over them.
  impl_->DrawSurface(scene, drawn.positions, o.colour_by, o.wireframe);
  glDisableClientState(GL_NORMAL_ARRAY);
  impl_->DrawContacts(drawn.positions);
  if (o.show_tool) impl_->DrawSuture(scene);
  if (scene.has_tool && (o.show_tool || o.show_force)) {
    const Camera around = AutoCamera(drawn.positions, 1);
    const double r = scene.tool_radius > 0 ? scene.tool_radius : 0.05 * Norm(Sub(around.eye, around.target));
    if (o.show_tool && scene.needle_length > 0) {
      glEnableClientState(GL_NORMAL_ARRAY);
      impl_->DrawNeedle(scene, cam, r, o.height);
      glDisableClientState(GL_NORMAL_ARRAY);
    }
    if (o.show_tool) impl_->DrawTool(scene, cam, r, o.height);
    glEnableClientState(GL_NORMAL_ARRAY);
    if (o.show_force) impl_->DrawForce(scene, r);
  }
  glFinish();
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) return *error = "GL error " + std::to_string(e), false;
  impl_->Legend(scene, o, lo, hi, out);
  return true;
}

const std::vector<int32_t>& Renderer::contacts() const { return impl_->contacts; }

Camera CameraFor(const SceneView& scene, const RenderOptions& o) {
  if (!o.camera.automatic) return o.camera;
  const double aspect = static_cast<double>(o.width) / o.height;
  const double r = scene.tool_radius;
  if (!scene.has_tool || !(r > 0) || !(o.show_tool || o.show_force)) return AutoCamera(scene.positions, aspect);
  // The tool, and the arrow's first tool radius beyond it: framing the whole arrow (up to four
  // radii) left the tissue, the subject, a fifth of the image's width; the arrow's direction and
  // the force plots say the rest.
  const Vec3 f{scene.force[0], scene.force[1], scene.force[2]};
  const double magnitude = Norm(f);
  const double reach = o.show_force && magnitude > 1e-9 ? (r + std::min(r, ArrowLength(r, magnitude))) / magnitude : 0;
  // A needle's tail too: the shaft is in view.
  const double tail = o.show_tool ? scene.needle_length : 0;
  const std::array<double, 4> spheres[3] = {
      {scene.tool_pos[0], scene.tool_pos[1], scene.tool_pos[2], r},
      {scene.tool_pos[0] + f[0] * reach, scene.tool_pos[1] + f[1] * reach, scene.tool_pos[2] + f[2] * reach, 0.2 * r},
      {scene.tool_pos[0] - scene.needle_axis[0] * tail, scene.tool_pos[1] - scene.needle_axis[1] * tail,
       scene.tool_pos[2] - scene.needle_axis[2] * tail, r}};
  return AutoCamera(scene.positions, aspect, std::span(spheres, tail > 0 ? 3 : 2));
}

bool Renderer::Project(const std::array<double, 3>& p, double* x, double* y) const {
  const std::array<double, 4> clip = Mul(impl_->proj, Mul(impl_->view, {p[0], p[1], p[2], 1}));
  if (clip[3] <= 0) return false;
  *x = (clip[0] / clip[3] + 1) * 0.5 * impl_->width;
  *y = (1 - clip[1] / clip[3]) * 0.5 * impl_->height;
  return true;
}

Camera AutoCamera(std::span<const float> positions, double aspect, std::span<const std::array<double, 4>> spheres) {
  Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (size_t i = 0; i + 2 < positions.size(); i += 3) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], static_cast<double>(positions[i + k]));
      hi[k] = std::max(hi[k], static_cast<double>(positions[i + k]));
    }
  }
  if (positions.size() < 3) lo = hi = {0, 0, 0};
  for (const std::array<double, 4>& b : spheres) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], b[k] - b[3]);
      hi[k] = std::max(hi[k], b[k] + b[3]);
    }
  }
  const Vec3 centre = Scale({lo[0] + hi[0], lo[1] + hi[1], lo[2] + hi[2]}, 0.5);
  const double radius = std::max(0.5 * Norm(Sub(hi, lo)), 1e-3);
  // From above, in front, a little right; back off until every corner of the box is in view:
  // a corner q (from the centre) needs |q.s| <= tan(half_x) (d + q.f), and the same for q.u.
  const Vec3 dir = Normalized({0.25, -0.75, 1.0});
  const Vec3 f = Scale(dir, -1);
  const Vec3 s = Normalized(Cross(f, {0, 0, 1}));
  const Vec3 u = Cross(s, f);
  const double tan_y = std::tan(kFovYDeg * kPi / 360), tan_x = tan_y * aspect;
  double distance = radius * 0.5;
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3 q = Sub({corner & 1 ? hi[0] : lo[0], corner & 2 ? hi[1] : lo[1], corner & 4 ? hi[2] : lo[2]}, centre);
    distance = std::max({distance, std::abs(Dot(q, s)) / tan_x - Dot(q, f), std::abs(Dot(q, u)) / tan_y - Dot(q, f)});
  }
  distance *= 1.08;  // a margin
  Camera c;
  c.automatic = false;
  c.target = centre;
  c.eye = {centre[0] + dir[0] * distance, centre[1] + dir[1] * distance, centre[2] + dir[2] * distance};
  return c;
}

}  // namespace idms::render
