// Scene -> StepOptions, ToolCommand and Registration.
#include "idms/agent/setup.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "idms/protocol/scene.h"
#include "idms/sim/interaction_script.h"

namespace idms::agent {

v1::Scene DefaultScene(const std::string& script, v1::Preset preset) {
  v1::Scene scene;
  v1::Tool* tool = scene.add_tools();
  if (script == "pierce" || script == "stitch" || script == "suture") {
    // The needle the script is made for (PierceNeedle, StitchNeedle, SutureScriptNeedle), the rest
    // of its fields the defaults.
    const ToolCommand c = script == "suture"   ? SutureScriptNeedle()
                          : script == "stitch" ? StitchNeedle()
                                               : PierceNeedle();
    tool->set_kind(v1::Tool::KIND_NEEDLE);
    tool->set_name("needle");
    tool->set_radius(c.radius);
    tool->set_stiffness(c.stiffness);
    tool->set_force_law(v1::FORCE_LAW_LINEAR);
    v1::Needle* n = tool->mutable_needle();
    n->set_length(c.needle.length);
    n->set_puncture_force(c.needle.puncture_force);
    n->set_axial_friction(c.needle.mu);
    n->set_grip(c.needle.grip);
    n->set_capture_radius(c.needle.capture_radius);
    n->set_lateral_stiffness(c.needle.lateral_stiffness);
    n->set_axial_stiffness(c.needle.axial_stiffness);
    if (c.suture.length > 0) {
      v1::Suture* u = n->mutable_suture();
      u->set_length(c.suture.length);
      u->set_segments(static_cast<uint32_t>(c.suture.segments));
      u->set_mass(c.suture.mass);
      if (script == "suture") {
        u->set_tie_force(c.suture.tie_force);
        u->set_hold_stiffness(c.suture.hold_stiffness);
      }
    }
    if (script == "suture") {
      // Its window: the tissue around each hole moves as the wound is drawn together; and the
      // scalpel that opens the incision first (the script changes to it, then to the needle).
      tool->set_local_radius(kSutureLocalRadius);
      v1::Tool* scalpel = scene.add_tools();
      scalpel->set_kind(v1::Tool::KIND_SCALPEL);
      scalpel->set_name("scalpel");
      scalpel->set_radius(0.05);
      scalpel->set_stiffness(400);
      scalpel->set_blade_length(kSutureBlade);
    }
  } else {
    tool->set_kind(script == "pluck" ? v1::Tool::KIND_TWEEZERS : v1::Tool::KIND_SPHERE);
    tool->set_name(script == "pluck" ? "tweezers" : "finger");
    tool->set_radius(1.5);
    tool->set_stiffness(400);
  }
  scene.set_preset(preset);
  scene.set_dt_s(0.001);
  scene.mutable_device()->set_max_force(8);
  ApplySceneDefaults(&scene);
  return scene;
}

bool ApplyFrictionSpec(const std::string& spec, v1::Scene* scene, std::string* error) {
  ToolCommand parsed;
  FrictionGiven has;
  if (!ParseFrictionSpec(spec, &parsed, &has, error)) {
    *error = "--friction: " + *error;
    return false;
  }
  for (v1::Tool& t : *scene->mutable_tools()) {
    if (t.kind() == v1::Tool::KIND_SCALPEL) continue;
    t.clear_static_friction(), t.clear_kinetic_friction(), t.clear_friction_stiffness(), t.clear_friction_damping();
    t.set_static_friction(parsed.mu_s);
    if (has.mu_d) t.set_kinetic_friction(parsed.mu_d);
    if (has.k_t) t.set_friction_stiffness(parsed.friction_stiffness);
    if (has.b_t) t.set_friction_damping(parsed.friction_damping);
  }
  if (!ValidateScene(*scene, error)) {
    *error = "--friction: " + *error;
    return false;
  }
  ApplySceneDefaults(scene);
  return true;
}

bool ApplyPassivitySpec(const std::string& spec, const std::string& device_spec, v1::Scene* scene, std::string* error) {
  v1::Passivity* p = scene->mutable_device()->mutable_passivity();
  // on|off first, then KEY=VALUE items.
  size_t start = 0;
  bool first = true;
  while (!spec.empty() && start <= spec.size()) {
    const size_t comma = std::min(spec.find(',', start), spec.size());
    const std::string item = spec.substr(start, comma - start);
    start = comma + 1;
    if (first && (item == "on" || item == "off")) {
      p->set_enabled(item == "on");
      first = false;
      continue;
    }
    first = false;
    const size_t eq = item.find('=');
    const std::string key = item.substr(0, eq);
    double value = 0;
    bool number = eq != std::string::npos;
    if (number) {
      const std::string text = item.substr(eq + 1);
      char* end = nullptr;
      value = std::strtod(text.c_str(), &end);
      number = !text.empty() && end == text.c_str() + text.size() && std::isfinite(value);
    }
    if (number && key == "window") {
      p->set_window_s(value);
    } else if (number && key == "max_damping") {
      p->set_max_damping(value);
    } else if (number && key == "quantum") {
      p->set_encoder_quantum(value);
    } else {
      *error =
          "--passivity: bad item '" + item + "' (expected on|off[,window=S,max_damping=B,quantum=Q], finite numbers)";
      return false;
    }
  }
  // Unset: on for a real device, off for the simulated ones and the thesis's preset.
  if (!p->has_enabled()) {
    p->set_enabled(device_spec.rfind("udp:", 0) == 0 && scene->preset() != v1::PRESET_THESIS);
  }
  if (!ValidateScene(*scene, error)) {
    *error = "--passivity: " + *error;
    return false;
  }
  ApplySceneDefaults(scene);
  return true;
}

PassivityOptions PassivityFromScene(const v1::Scene& scene, const Registration& registration, double dt_s) {
  const v1::Passivity& p = scene.device().passivity();
  PassivityOptions o;
  o.enabled = p.enabled();
  o.dt_s = dt_s;
  o.window_s = p.window_s();
  // Device units to model units: a length is scale times, a force 1 / force_scale times.
  o.max_damping = p.max_damping() / (registration.force_scale * registration.scale);
  o.quantum = p.encoder_quantum() * registration.scale;
  return o;
}

namespace {

// Scene.tools(i) as the step takes it. False with a message naming the field.
bool ToolFromScene(const v1::Scene& scene, int i, ToolCommand* tool, std::string* error) {
  const v1::Tool& t = scene.tools(i);
  ToolCommand c;
  switch (t.kind()) {
    case v1::Tool::KIND_TWEEZERS:
      c.kind = ToolKind::kTweezers;
      break;
    case v1::Tool::KIND_SCALPEL:
      c.kind = ToolKind::kScalpel;
      break;
    case v1::Tool::KIND_NEEDLE:
      c.kind = ToolKind::kNeedle;  // its axis stays -z until the device sample carries an orientation
      break;
    default:
      c.kind = ToolKind::kSphere;
      break;
  }
  c.radius = t.radius();
  c.stiffness = t.stiffness();
  if (t.has_blade_length()) c.blade[2] = -t.blade_length();
  c.law = t.force_law() == v1::FORCE_LAW_LINEAR ? ContactLaw::kLinear : ContactLaw::kThesis;  // unspecified = thesis
  // Friction (unset: frictionless; ApplySceneDefaults filled the rest where mu_s > 0).
  c.mu_s = t.static_friction();
  c.mu_d = t.has_kinetic_friction() ? t.kinetic_friction() : t.static_friction();
  c.friction_stiffness = t.friction_stiffness();                              // 0 = the tool's stiffness
  c.friction_damping = t.has_friction_damping() ? t.friction_damping() : -1;  // < 0 = k_t dt
  // The needle's parameters where the scene sets them (the rest: NeedleParams' defaults).
  const v1::Needle& n = t.needle();
  NeedleParams& np = c.needle;
  if (n.has_length()) np.length = n.length();
  if (n.has_puncture_force()) np.puncture_force = n.puncture_force();
  if (n.has_axial_friction()) np.mu = n.axial_friction();
  if (n.has_grip()) np.grip = n.grip();
  if (n.has_capture_radius()) np.capture_radius = n.capture_radius();
  if (n.has_lateral_stiffness()) np.lateral_stiffness = n.lateral_stiffness();
  if (n.has_lateral_damping()) np.lateral_damping = n.lateral_damping();
  if (n.has_axial_stiffness()) np.axial_stiffness = n.axial_stiffness();
  if (n.has_axial_damping()) np.axial_damping = n.axial_damping();
  // Its thread where the scene gives one (the rest: SutureParams' defaults).
  if (n.has_suture()) {
    const v1::Suture& u = n.suture();
    SutureParams& sp = c.suture;
    sp.length = u.length();
    if (u.has_segments()) sp.segments = static_cast<int32_t>(u.segments());
    if (u.has_mass()) sp.mass = u.mass();
    if (u.has_stiffness()) sp.stiffness = u.stiffness();
    if (u.has_damping()) sp.damping = u.damping();
    if (u.has_strength()) sp.strength = u.strength();
    if (u.has_hold_stiffness()) sp.hold_stiffness = u.hold_stiffness();
    if (u.has_tie_force()) sp.tie_force = u.tie_force();
    if (u.has_tie_speed()) sp.tie_speed = u.tie_speed();
    if (u.has_drag()) sp.drag = u.drag();
    if (!ValidateSuture(c, error)) {
      *error = "scene: tools[" + std::to_string(i) + "].needle." + *error;
      return false;
    }
  }
  *tool = c;
  return true;
}

}  // namespace

bool SceneTools(const v1::Scene& scene, std::array<ToolCommand, kMaxTools>* tools, int32_t* num_tools,
                std::string* error) {
  *num_tools = 0;
  for (int i = 0; i < scene.tools_size() && i < kMaxTools; ++i) {
    if (!ToolFromScene(scene, i, &(*tools)[i], error)) return false;
    *num_tools = i + 1;
  }
  return true;
}

bool SceneToLoop(const v1::Scene& scene, StepOptions* step, ToolCommand* tool, Registration* registration,
                 std::string* error) {
  if (scene.tools_size() < 1 || scene.tools_size() > kMaxTools) {
    *error = "scene: tools: the agent's one device holds one of 1 to " + std::to_string(kMaxTools) + " tools, got " +
             std::to_string(scene.tools_size());
    return false;
  }
  // Step options.
  StepOptions o;
  o.dt_s = scene.dt_s();
  switch (scene.integrator()) {
    case v1::INTEGRATOR_SYMPLECTIC_EULER:
      o.integrator = Integrator::kSymplecticEuler;
      break;
    case v1::INTEGRATOR_RK4:
      o.integrator = Integrator::kRk4;
      break;
    case v1::INTEGRATOR_BACKWARD_EULER:
      o.integrator = Integrator::kImplicitEuler;
      break;
    default:
      o.integrator = Integrator::kExplicitEuler;
      break;
  }
  o.full = scene.full_simulation();
  const v1::Vec3& g = scene.gravity();
  o.gravity = g.x() != 0 || g.y() != 0 || g.z() != 0;
  o.gravity_accel[0] = g.x(), o.gravity_accel[1] = g.y(), o.gravity_accel[2] = g.z();
  o.air_damping = scene.air_resistance();
  const v1::Tool& t = scene.tools(0);
  o.local_radius = t.local_radius();
  // Device limits are in device force units; the step clamps in model force units.
  const v1::DeviceMapping& d = scene.device();
  o.max_device_force = d.max_force() / d.force_scale();
  o.max_device_force_rate =
      d.max_force_rate() > 0 ? d.max_force_rate() / d.force_scale() : std::numeric_limits<double>::max();
  o.transition_force_rate = d.transition_force_rate() / d.force_scale();
  *step = o;

  // The tool the device holds first.
  if (!ToolFromScene(scene, 0, tool, error)) return false;

  // Registration: p_model = scale * Rz Ry Rx * p_device + offset.
  Registration r;
  r.scale = d.scale();
  const double rpy[3] = {d.rotation_rpy_deg().x(), d.rotation_rpy_deg().y(), d.rotation_rpy_deg().z()};
  if (!RotationFromRpyDeg(rpy, r.rot, error)) {
    *error = "scene: device.rotation_rpy_deg: " + *error;
    return false;
  }
  r.offset[0] = d.offset().x(), r.offset[1] = d.offset().y(), r.offset[2] = d.offset().z();
  r.force_scale = d.force_scale();
  r.max_force = d.max_force();
  *registration = r;
  return true;
}

}  // namespace idms::agent
