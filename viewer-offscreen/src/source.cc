// Frame sources: a model at rest (encoder -> keyframe -> mirror) and recordings (reader -> mirror).
#include "idms/render/source.h"

#include <google/protobuf/text_format.h>

#include <algorithm>
#include <cmath>

#include "idms/protocol/mesh_codec.h"
#include "idms/render/display.h"
#include "idms/sim/model.h"
#include "idms/sim/model_io.h"
#include "idms/sim/tool.h"

namespace idms::render {

SceneView ViewerState::View() const {
  SceneView v;
  v.positions = mirror.positions();
  v.triangles = mirror.triangles();
  v.has_tool = has_sample;
  // The tool the device held at the last sample (the suture's scalpel, then its needle).
  const int held =
      has_sample && static_cast<int>(sample.tool_index()) < num_tools ? static_cast<int>(sample.tool_index()) : 0;
  v.tool_radius = num_tools > 0 ? tool_radii[held] : tool_radius;
  const double held_needle = num_tools > 0 ? needle_lengths[held] : needle_length;
  v.mm_per_unit = mm_per_unit;
  v.newtons_per_force_unit = newtons_per_force_unit;
  if (has_sample) {
    v.tool_pos = {sample.tool_pos().x(), sample.tool_pos().y(), sample.tool_pos().z()};
    v.force = {sample.force().x(), sample.force().y(), sample.force().z()};
    v.friction_force = {sample.friction_force().x(), sample.friction_force().y(), sample.friction_force().z()};
    v.slip = sample.friction() == v1::FRICTION_SLIP;
    v.contact = sample.contact();
    v.grasp = sample.grasp();
    if (held_needle > 0) {
      v.needle_length = held_needle;
      v.needle_punctured = sample.needle_punctured();
      if (sample.has_tool_orientation()) {
        const v1::Quat& q = sample.tool_orientation();
        const double w[4] = {q.w(), q.x(), q.y(), q.z()};
        NeedleAxisOf(w, v.needle_axis.data());
      }
    }
  }
  const v1::SutureShape& suture = mirror.suture();
  v.suture_nodes = std::span<const float>(suture.nodes().data(), static_cast<size_t>(suture.nodes_size()));
  v.suture_punctures = std::span<const float>(suture.punctures().data(), static_cast<size_t>(suture.punctures_size()));
  v.suture_broken = suture.broken_segment();
  if (rest.size() == v.positions.size()) v.rest = rest, v.rest_time_s = rest_time_s;
  if (stiffness.size() * 3 == v.positions.size()) v.stiffness = stiffness;
  return v;
}

void ViewerState::SetScene(const v1::Scene& scene) {
  num_tools = std::min<int>(scene.tools_size(), static_cast<int>(tool_radii.size()));
  for (int i = 0; i < num_tools; ++i) {
    const v1::Tool& t = scene.tools(i);
    tool_radii[i] = t.has_radius() ? t.radius() : 0;
    needle_lengths[i] = t.kind() != v1::Tool::KIND_NEEDLE ? 0
                        : t.needle().has_length()         ? t.needle().length()
                                                          : NeedleParams{}.length;
  }
  tool_radius = num_tools > 0 ? tool_radii[0] : 0;
  needle_length = num_tools > 0 ? needle_lengths[0] : 0;
  mm_per_unit = scene.units().mm_per_unit();
  newtons_per_force_unit = scene.units().newtons_per_force_unit();
}

bool ViewerState::Apply(const v1::Envelope& e, std::string* error) {
  if (e.has_mesh_keyframe() || e.has_mesh_delta()) {
    const MirrorStatus status = mirror.Apply(e, error);
    if (status == MirrorStatus::kInvalid) return false;
    // Rest: the first surface, or the first of a new size (a cut that exposed atoms).
    if (status == MirrorStatus::kOk && e.has_mesh_keyframe() && rest.size() != mirror.positions().size()) {
      rest.assign(mirror.positions().begin(), mirror.positions().end());
      rest_time_s = mirror.time_s();
    }
    return true;  // a gap keeps the last frame, as a viewer does until its next keyframe
  }
  if (e.has_device_samples() && e.device_samples().samples_size() > 0) {
    sample = e.device_samples().samples(e.device_samples().samples_size() - 1);
    has_sample = true;
  }
  return true;
}

bool LoadRestState(const Model& model, ViewerState* state, std::string* error) {
  // The surface at rest, encoded as a session's first keyframe and applied to the mirror.
  std::vector<double> surface(static_cast<size_t>(model.num_external) * 3);
  GatherSurface(model, model.atom_pos_eq, surface);
  MeshEncoder encoder;
  encoder.SetTopology(model.topology_version, SurfaceTriangles(model));
  v1::Envelope keyframe;
  if (!encoder.Encode(0, surface, &keyframe, error)) return false;
  state->has_sample = false;
  state->rest.clear();
  state->stiffness = StiffnessPerVertex(model);
  return state->Apply(keyframe, error);
}

bool LoadRestState(const std::string& prefix, ViewerState* state, std::string* error) {
  std::string fem, plg;
  ModelPaths(prefix, &fem, &plg);
  Model model;
  LoadError le;
  if (!LoadModel(fem, plg, ReadOptions{}, &model, &le)) return *error = le.ToString(), false;
  return LoadRestState(model, state, error);
}

bool LoadRestStateText(std::string_view fem, std::string_view plg, const std::string& name, ViewerState* state,
                       std::string* error) {
  Model model;
  LoadError le;
  if (!ParseModelText(fem, plg, name, &model, &le)) return *error = le.ToString(), false;
  FinalizeModel(model);
  return LoadRestState(model, state, error);
}

bool RecordingPlayer::Open(const std::string& path, std::string* error) {
  path_ = path;
  RecordingReaderOptions options;
  options.events = options.annotations = false;
  if (!reader_.Open(path, options, error)) return false;
  // The tool's radius from the recorded scene.
  const auto scene = reader_.session().find("scene");
  v1::Scene parsed;
  if (scene != reader_.session().end() && google::protobuf::TextFormat::ParseFromString(scene->second, &parsed))
    state_->SetScene(parsed);
  // Rest: the recording's first keyframe (the session's start), whatever time is asked for.
  RecordingReader first;
  RecordingReaderOptions mesh_only;
  mesh_only.device = mesh_only.events = mesh_only.annotations = false;
  if (!first.Open(path, mesh_only, error)) return false;
  RecordedMessage m;
  ViewerState start;
  while (start.rest.empty() && first.Next(&m, error)) {
    if (m.envelope.has_mesh_keyframe() && !start.Apply(m.envelope, error)) return *error = path + ": " + *error, false;
  }
  if (!error->empty()) return *error = path + ": " + *error, false;
  state_->rest = std::move(start.rest);
  state_->rest_time_s = start.rest_time_s;
  position_ns_ = reader_.start_ns();
  pending_.reset();
  at_end_ = false;
  return true;
}

bool RecordingPlayer::ReadNext(std::string* error) {
  if (at_end_) return false;
  RecordedMessage m;
  if (!reader_.Next(&m, error)) {
    at_end_ = true;
    return false;
  }
  pending_ = std::move(m);
  return true;
}

bool RecordingPlayer::MoveTo(double t_s, std::string* error) {
  error->clear();
  if (!(t_s >= 0 && t_s <= duration_s() + 1e-9)) {
    *error = "t=" + std::to_string(t_s) + " s is outside the recording (0 to " + std::to_string(duration_s()) + " s)";
    return false;
  }
  const uint64_t target = reader_.start_ns() + static_cast<uint64_t>(std::llround(t_s * 1e9));
  // Back in time, or far ahead: seek to the keyframe before. 100 ms early, so that the device
  // batch that was current at t_s is read too.
  constexpr uint64_t kLeadNs = 100'000'000, kFarNs = 2'000'000'000;
  if (target < position_ns_ || target - position_ns_ > kFarNs) {
    const uint64_t from = std::max(reader_.start_ns(), target > kLeadNs ? target - kLeadNs : 0);
    if (!reader_.Seek(from, error)) return false;
    pending_.reset();
    at_end_ = false;
    // A fresh mirror: frames from before the seek must not stand in for the surface at t_s.
    auto fresh = std::make_unique<ViewerState>();
    fresh->tool_radius = state_->tool_radius;
    fresh->needle_length = state_->needle_length;
    fresh->tool_radii = state_->tool_radii;
    fresh->needle_lengths = state_->needle_lengths;
    fresh->num_tools = state_->num_tools;
    fresh->mm_per_unit = state_->mm_per_unit;
    fresh->newtons_per_force_unit = state_->newtons_per_force_unit;
    fresh->rest = state_->rest;
    fresh->rest_time_s = state_->rest_time_s;
    state_ = std::move(fresh);
  }
  // Apply what was logged up to the target.
  while (true) {
    if (!pending_ && !ReadNext(error)) {
      if (!error->empty()) return *error = path_ + ": " + *error, false;
      break;
    }
    if (pending_->log_time_ns > target) break;
    if (!state_->Apply(pending_->envelope, error)) return *error = path_ + ": " + *error, false;
    pending_.reset();
  }
  position_ns_ = target;
  // Before the first keyframe (the session's first instants): the first surface there is.
  while (!state_->mirror.has_keyframe()) {
    if (!pending_ && !ReadNext(error)) {
      if (!error->empty()) return *error = path_ + ": " + *error, false;
      return *error = "the recording has no surface", false;
    }
    if (!state_->Apply(pending_->envelope, error)) return *error = path_ + ": " + *error, false;
    position_ns_ = pending_->log_time_ns;
    pending_.reset();
  }
  return true;
}

}  // namespace idms::render
