// Where frames come from: a model at rest, a recording at a session time, a live session. Each
// feeds a MeshMirror with the frames the protocol carries (for a model, one keyframe from the
// session encoder), so an image shows exactly what a viewer of the same frames saw.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "idms/protocol/mesh_mirror.h"
#include "idms/protocol/recording.h"
#include "idms/render/render.h"

namespace idms {
struct Model;
}

namespace idms::render {

// A mirror, the device's last sample, the tool's radius and the surface at rest: what a viewer holds.
struct ViewerState {
  MeshMirror mirror;
  bool has_sample = false;
  v1::DeviceSample sample;   // the last one received
  double tool_radius = 0;    // from the scene, its first tool (0 = unknown)
  double needle_length = 0;  // from the scene when its first tool is a needle (0 = not one)
  // Every tool's, in the scene's order: the device holds one (DeviceSample.tool_index).
  std::array<double, 4> tool_radii{}, needle_lengths{};
  int num_tools = 0;
  double mm_per_unit = 0;  // from the scene's units (0 = not declared)
  double newtons_per_force_unit = 0;
  // The surface at rest (display.json's rule, as the browser's): the first keyframe applied, or
  // the first of another number of vertices; a model's own rest; a recording's first keyframe.
  std::vector<float> rest;        // (num_vertices x 3), model units
  double rest_time_s = 0;         // its session time
  std::vector<double> stiffness;  // per vertex (a model's: StiffnessPerVertex); empty = unknown
  // A view of the above for Renderer::Render (valid while this state is unchanged).
  SceneView View() const;
  // Reads the tools' radii and needles' lengths, and the units, from a scene.
  void SetScene(const v1::Scene& scene);
  // Applies a mesh frame or takes a device batch; other bodies are ignored. False on a mesh frame
  // the mirror refuses (with *error). A keyframe sets rest when there is none of its size.
  bool Apply(const v1::Envelope& envelope, std::string* error);
};

// The model's surface at rest, through the mesh encoder and into the mirror.
bool LoadRestState(const Model& model, ViewerState* state, std::string* error);
// The same from PREFIX.fem + PREFIX.plg.
bool LoadRestState(const std::string& prefix, ViewerState* state, std::string* error);
// The same from the files' text (the server's library blobs).
bool LoadRestStateText(std::string_view fem, std::string_view plg, const std::string& name, ViewerState* state,
                       std::string* error);

// A recording played to any session time, as a viewer of /ws/replay would hold it. Owned by one
// thread. Moving forward reads on; moving back seeks through the keyframe index.
class RecordingPlayer {
 public:
  bool Open(const std::string& path, std::string* error);
  double duration_s() const { return (reader_.end_ns() - reader_.start_ns()) * 1e-9; }
  // Applies every message logged up to session time t_s (seconds from the first message; within
  // [0, duration_s()]); before the first keyframe, reads on to it. False with *error on malformed
  // data, a time outside the recording, or a recording without a surface.
  bool MoveTo(double t_s, std::string* error);
  const ViewerState& state() const { return *state_; }

 private:
  bool ReadNext(std::string* error);  // fills pending_; false at the end (error empty) or on error

  RecordingReader reader_;
  std::string path_;
  std::unique_ptr<ViewerState> state_ = std::make_unique<ViewerState>();  // new after each seek
  std::optional<RecordedMessage> pending_;
  bool at_end_ = false;
  uint64_t position_ns_ = 0;  // everything logged at or before it is applied
};

}  // namespace idms::render
