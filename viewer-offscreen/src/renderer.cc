// The OSMesa renderer: fixed-function GL (llvmpipe), one context made in the constructor and
// reused; client-side vertex arrays straight from the mirror's positions, per-vertex normals
// recomputed each frame (area-weighted) for smooth shading, a depth buffer, two-sided lighting.
#include <GL/osmesa.h>

#include <algorithm>
#include <cmath>

#include "idms/render/render.h"

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

// Unit-radius sphere and unit-length arrow (shaft and head along +z), built once.
struct Shape {
  std::vector<float> pos, normal;
  std::vector<uint32_t> tris;
  void Add(const Vec3& p, const Vec3& n) {
    for (int i = 0; i < 3; ++i) pos.push_back(static_cast<float>(p[i])), normal.push_back(static_cast<float>(n[i]));
  }
};

Shape MakeSphere(int slices, int stacks) {
  Shape s;
  for (int i = 0; i <= stacks; ++i) {
    const double theta = kPi * i / stacks;
    for (int j = 0; j <= slices; ++j) {
      const double phi = 2 * kPi * j / slices;
      const Vec3 p{std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
      s.Add(p, p);
    }
  }
  for (int i = 0; i < stacks; ++i) {
    for (int j = 0; j < slices; ++j) {
      const uint32_t a = static_cast<uint32_t>(i * (slices + 1) + j), b = a + static_cast<uint32_t>(slices + 1);
      s.tris.insert(s.tris.end(), {a, b, a + 1, a + 1, b, b + 1});
    }
  }
  return s;
}

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

}  // namespace

struct Renderer::Impl {
  OSMesaContext ctx = nullptr;
  std::vector<float> normals;  // (num_vertices x 3), reused
  Shape sphere = MakeSphere(32, 20), arrow = MakeArrow(20);
  Mat4 view{}, proj{};
  int width = 0, height = 0;

  ~Impl() {
    if (ctx != nullptr) OSMesaDestroyContext(ctx);
  }

  // Area-weighted vertex normals: each triangle adds its unnormalized normal to its corners.
  void ComputeNormals(const SceneView& scene) {
    const size_t nv = scene.positions.size() / 3;
    normals.assign(nv * 3, 0.0f);
    const float* p = scene.positions.data();
    const int32_t* t = scene.triangles.data();
    for (size_t i = 0; i + 2 < scene.triangles.size(); i += 3) {
      const float* a = p + 3 * t[i];
      const float* b = p + 3 * t[i + 1];
      const float* c = p + 3 * t[i + 2];
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

  // Projection and view: near and far planes around everything drawn.
  void SetCamera(const SceneView& scene, const RenderOptions& o) {
    const double aspect = static_cast<double>(o.width) / o.height;
    const Camera cam = CameraFor(scene, o);
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

  void DrawSurface(const SceneView& scene, bool wireframe) {
    glVertexPointer(3, GL_FLOAT, 0, scene.positions.data());
    glNormalPointer(GL_FLOAT, 0, normals.data());
    const GLsizei n = static_cast<GLsizei>(scene.triangles.size());
    if (wireframe) {
      glDisable(GL_LIGHTING);
      glColor3f(kWireColour[0], kWireColour[1], kWireColour[2]);
      glPolygonMode(GL_FRONT_AND_BACK, GL_LINE);
      glDrawElements(GL_TRIANGLES, n, GL_UNSIGNED_INT, scene.triangles.data());
      glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
      glEnable(GL_LIGHTING);
      return;
    }
    SetMaterial(GL_FRONT, kTissue, 0.15f);
    SetMaterial(GL_BACK, kTissueBack, 0.05f);
    glDrawElements(GL_TRIANGLES, n, GL_UNSIGNED_INT, scene.triangles.data());
  }

  // The tool sphere at the device position, and the force arrow from its surface.
  void DrawTool(const SceneView& scene, const RenderOptions& o, double fallback_radius) {
    const double r = scene.tool_radius > 0 ? scene.tool_radius : fallback_radius;
    if (o.show_tool) {
      glPushMatrix();
      glTranslated(scene.tool_pos[0], scene.tool_pos[1], scene.tool_pos[2]);
      glScaled(r, r, r);
      SetMaterial(GL_FRONT_AND_BACK, kToolColour, 0.4f);
      DrawShape(sphere);
      glPopMatrix();
    }
    const Vec3 f{scene.force[0], scene.force[1], scene.force[2]};
    const double magnitude = Norm(f);
    if (!o.show_force || !(magnitude > 1e-9)) return;
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
    SetMaterial(GL_FRONT_AND_BACK, kForceColour, 0.3f);
    DrawShape(arrow);
    glPopMatrix();
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
  // Bind the image as the colour buffer (rows top first); the context stays the same.
  out->width = o.width;
  out->height = o.height;
  out->rgba.resize(static_cast<size_t>(o.width) * o.height * 4);
  if (!OSMesaMakeCurrent(impl_->ctx, out->rgba.data(), GL_UNSIGNED_BYTE, o.width, o.height))
    return *error = "OSMesaMakeCurrent failed", false;
  OSMesaPixelStore(OSMESA_Y_UP, 0);
  impl_->width = o.width;
  impl_->height = o.height;
  impl_->ComputeNormals(scene);
  impl_->SetCamera(scene, o);
  // Fixed state: depth test, smooth shading, one directional light fixed to the eye.
  glViewport(0, 0, o.width, o.height);
  glClearColor(kBackground[0], kBackground[1], kBackground[2], 1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glShadeModel(GL_SMOOTH);
  glEnable(GL_LIGHTING);
  glEnable(GL_LIGHT0);
  glEnable(GL_RESCALE_NORMAL);
  glLightModeli(GL_LIGHT_MODEL_TWO_SIDE, GL_TRUE);
  const float ambient[4] = {0.28f, 0.28f, 0.28f, 1}, diffuse[4] = {0.80f, 0.80f, 0.80f, 1},
              specular[4] = {0.6f, 0.6f, 0.6f, 1}, none[4] = {0, 0, 0, 1};
  const float light_dir[4] = {kLightDirEye[0], kLightDirEye[1], kLightDirEye[2], 0};
  glLightModelfv(GL_LIGHT_MODEL_AMBIENT, ambient);
  glLightfv(GL_LIGHT0, GL_AMBIENT, none);
  glLightfv(GL_LIGHT0, GL_DIFFUSE, diffuse);
  glLightfv(GL_LIGHT0, GL_SPECULAR, specular);
  glMatrixMode(GL_PROJECTION);
  glLoadMatrixd(impl_->proj.data());
  glMatrixMode(GL_MODELVIEW);
  glLoadIdentity();
  glLightfv(GL_LIGHT0, GL_POSITION, light_dir);
  glLoadMatrixd(impl_->view.data());
  glEnableClientState(GL_VERTEX_ARRAY);
  glEnableClientState(GL_NORMAL_ARRAY);
  // The surface, then the tool and the force.
  impl_->DrawSurface(scene, o.wireframe);
  if (scene.has_tool && (o.show_tool || o.show_force)) {
    const Camera cam = AutoCamera(scene.positions, 1);
    impl_->DrawTool(scene, o, 0.05 * Norm(Sub(cam.eye, cam.target)));
  }
  glFinish();
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) return *error = "GL error " + std::to_string(e), false;
  return true;
}

Camera CameraFor(const SceneView& scene, const RenderOptions& o) {
  if (!o.camera.automatic) return o.camera;
  const double aspect = static_cast<double>(o.width) / o.height;
  const double r = scene.tool_radius;
  if (!scene.has_tool || !(r > 0) || !(o.show_tool || o.show_force)) return AutoCamera(scene.positions, aspect);
  // The tool, and the arrow's tip (its head is 0.2 radii wide).
  const Vec3 f{scene.force[0], scene.force[1], scene.force[2]};
  const double magnitude = Norm(f);
  const double reach = o.show_force && magnitude > 1e-9 ? (r + ArrowLength(r, magnitude)) / magnitude : 0;
  const std::array<double, 4> spheres[2] = {
      {scene.tool_pos[0], scene.tool_pos[1], scene.tool_pos[2], r},
      {scene.tool_pos[0] + f[0] * reach, scene.tool_pos[1] + f[1] * reach, scene.tool_pos[2] + f[2] * reach, 0.2 * r}};
  return AutoCamera(scene.positions, aspect, spheres);
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
