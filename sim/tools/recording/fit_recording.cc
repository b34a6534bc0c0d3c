#include "fit_recording.h"

#include <algorithm>
#include <cmath>

#include "idms/agent/setup.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/protocol/recording.h"
#include "idms/protocol/scene.h"

namespace idms::tool {
namespace {

const char* KindName(ToolKind kind) {
  switch (kind) {
    case ToolKind::kSphere:
      return "sphere";
    case ToolKind::kTweezers:
      return "tweezers";
    case ToolKind::kScalpel:
      return "scalpel";
    case ToolKind::kNeedle:
      return "needle";
    case ToolKind::kNone:
      break;
  }
  return "tool";
}

// The first keyframe against the model's rest surface: the same vertex count and every vertex
// within `tolerance` of its rest position.
bool SameSurface(const MeshMirror& mirror, const Model& model, const std::string& path, std::string* error) {
  const int32_t n = static_cast<int32_t>(model.external_atoms.size());
  if (mirror.num_vertices() != n) {
    *error = path + ": its model has " + std::to_string(mirror.num_vertices()) + " surface vertices, the model given " +
             std::to_string(n) + ": not the model it was recorded on";
    return false;
  }
  constexpr double kTolerance = 0.01;  // model units: far above the quantum, far below an element
  const std::span<const float> p = mirror.positions();
  for (int32_t v = 0; v < n; ++v) {
    const double* rest = &model.atom_pos_eq[3 * model.external_atoms[v]];
    const double d = std::hypot(p[3 * v] - rest[0], p[3 * v + 1] - rest[1], p[3 * v + 2] - rest[2]);
    if (!(d <= kTolerance)) {
      *error = path + ": surface vertex " + std::to_string(v) + " starts " + std::to_string(d) +
               " model units from its rest position in the model given: not the model it was recorded on";
      return false;
    }
  }
  return true;
}

}  // namespace

bool ReadRecordingTrace(const std::string& path, const Model& model, fit::Trace* trace, StepOptions* step,
                        ToolCommand* tool, std::string* error) {
  RecordingReader reader;
  RecordingReaderOptions options;
  options.annotations = false;
  if (!reader.Open(path, options, error)) return false;
  const auto scene_text = reader.session().find("scene");
  if (scene_text == reader.session().end()) {
    *error = path + ": no scene in its idms.session metadata: not a session recording of idms-server";
    return false;
  }
  v1::Scene scene;
  std::string why;
  if (!LoadSceneText(scene_text->second, path + " (its scene)", &scene, &why)) {
    *error = why;
    return false;
  }
  agent::Registration registration;
  if (!agent::SceneToLoop(scene, step, tool, &registration, &why)) {
    *error = path + ": " + why;
    return false;
  }
  // The tweezers replay closed where the recording held an atom (its grasp flag stands for the
  // button, as replay:FILE.mcap has it); a cut or a needle's puncture is not replayed.
  if (tool->kind != ToolKind::kSphere && tool->kind != ToolKind::kTweezers) {
    *error = path + ": the session's tool is the " + KindName(tool->kind) +
             "; the fitter replays a sphere MIO or the tweezers (a cut or a puncture is not replayed)";
    return false;
  }
  const bool tweezers = tool->kind == ToolKind::kTweezers;
  *trace = {};
  trace->dt_s = step->dt_s;
  MeshMirror mirror;
  bool surface_checked = false;
  int64_t next_tick = 0, passive_ticks = 0;
  RecordedMessage m;
  while (reader.Next(&m, error)) {
    const v1::Envelope& e = m.envelope;
    if (e.has_mesh_keyframe() && !surface_checked) {
      if (mirror.Apply(e.mesh_keyframe(), &why) != MirrorStatus::kOk) {
        *error = path + ": its first mesh keyframe does not decode: " + why;
        return false;
      }
      if (!SameSurface(mirror, model, path, error)) return false;
      surface_checked = true;
    } else if (e.has_session_event() && e.session_event().kind() == v1::SessionEvent::KIND_RESET) {
      *error = path + ": the session was reset after tick " + std::to_string(next_tick) +
               "; the fitter replays one run from rest (cut the recording at the reset)";
      return false;
    } else if (e.has_device_samples()) {
      for (const v1::DeviceSample& s : e.device_samples().samples()) {
        if (static_cast<int64_t>(s.tick()) != next_tick) {
          *error = path + (next_tick == 0 ? ": it starts at tick " + std::to_string(s.tick()) +
                                                ", not at the session's first: the tissue's state there is unknown"
                                          : ": ticks " + std::to_string(next_tick) + " to " +
                                                std::to_string(s.tick() - 1) + " are missing (the session lost them)");
          return false;
        }
        ++next_tick;
        if (s.passivity_damping() != 0) ++passive_ticks;
        trace->pos.push_back({s.tool_pos().x(), s.tool_pos().y(), s.tool_pos().z()});
        trace->force.push_back({s.force().x(), s.force().y(), s.force().z()});
        if (tweezers) trace->closed.push_back(s.grasp() ? 1 : 0);
      }
    }
  }
  if (!error->empty()) return false;
  if (!surface_checked) {
    *error = path + ": no mesh keyframe: nothing to check the model against";
    return false;
  }
  if (passive_ticks > 0) {
    *error = path + ": the passivity controller added damping on " + std::to_string(passive_ticks) +
             " ticks: the recorded force is not the tissue's alone (record with passivity off to fit)";
    return false;
  }
  if (trace->pos.size() < 2) {
    *error = path + ": fewer than two ticks recorded";
    return false;
  }
  return true;
}

}  // namespace idms::tool
