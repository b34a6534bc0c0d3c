// Scene -> StepOptions, ToolCommand and Registration.
#include "idms/agent/setup.h"

#include <limits>

#include "idms/protocol/scene.h"

namespace idms::agent {

v1::Scene DefaultScene(const std::string& script, v1::Preset preset) {
  v1::Scene scene;
  v1::Tool* tool = scene.add_tools();
  tool->set_kind(script == "pluck" ? v1::Tool::KIND_TWEEZERS : v1::Tool::KIND_SPHERE);
  tool->set_name(script == "pluck" ? "tweezers" : "finger");
  tool->set_radius(1.5);
  tool->set_stiffness(400);
  scene.set_preset(preset);
  scene.set_dt_s(0.001);
  scene.mutable_device()->set_max_force(8);
  ApplySceneDefaults(&scene);
  return scene;
}

bool SceneToLoop(const v1::Scene& scene, StepOptions* step, ToolCommand* tool, Registration* registration,
                 std::string* error) {
  if (scene.tools_size() != 1) {
    *error = "scene: tools: the agent drives exactly one tool with its one device, got " +
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

  // The tool.
  ToolCommand c;
  switch (t.kind()) {
    case v1::Tool::KIND_TWEEZERS:
      c.kind = ToolKind::kTweezers;
      break;
    case v1::Tool::KIND_SCALPEL:
      c.kind = ToolKind::kScalpel;
      break;
    default:
      c.kind = ToolKind::kSphere;
      break;
  }
  c.radius = t.radius();
  c.stiffness = t.stiffness();
  c.law = t.force_law() == v1::FORCE_LAW_LINEAR ? ContactLaw::kLinear : ContactLaw::kThesis;  // unspecified = thesis
  *tool = c;

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
