// The checks at the door of the server's WebSockets (frame_checks.h).
#include "frame_checks.h"

#include <cmath>

#include "idms/protocol/envelope.h"

namespace idms::server {
namespace {

bool Fail(std::string* error, std::string what) {
  *error = std::move(what);
  return false;
}

bool TimeOk(double t_s) { return std::isfinite(t_s) && t_s >= 0 && t_s <= kMaxSessionTimeS; }

std::string TimeError(const std::string& field, double t_s) {
  return field + " " + std::to_string(t_s) + " is not a session time (finite, 0 to " +
         std::to_string(static_cast<int64_t>(kMaxSessionTimeS)) + " s)";
}

bool VecOk(const v1::Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

// Unit within what a float's rounding (a device's own quaternion) leaves: 1 +- 1e-3.
bool QuatOk(const v1::Quat& q) {
  const double n = q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z();
  return std::isfinite(n) && std::abs(n - 1) <= 2e-3;
}

bool SizeOk(const std::string& s, size_t max, const char* field, std::string* error) {
  if (s.size() <= max) return true;
  return Fail(error, std::string(field) + " has " + std::to_string(s.size()) + " bytes; at most " +
                         std::to_string(max) + " are kept");
}

}  // namespace

bool CheckAgentHello(const v1::Hello& hello, std::string* error) {
  if (!SizeOk(hello.identity(), kMaxIdentityBytes, "Hello.identity", error)) return false;
  if (!SizeOk(hello.device(), kMaxIdentityBytes, "Hello.device", error)) return false;
  if (!SizeOk(hello.trainee(), kMaxIdentityBytes, "Hello.trainee", error)) return false;
  if (!SizeOk(hello.session_id(), 64, "Hello.session_id", error)) return false;
  if (!SizeOk(hello.resume_token(), 128, "Hello.resume_token", error)) return false;
  if (!SizeOk(hello.scene().model(), kMaxIdentityBytes, "Hello.scene.model", error)) return false;
  if (!SizeOk(hello.scene().model_file(), 4096, "Hello.scene.model_file", error)) return false;
  const size_t scene_bytes = hello.scene().ByteSizeLong();
  if (scene_bytes > kMaxSceneBytes) {
    return Fail(error, "Hello.scene has " + std::to_string(scene_bytes) + " bytes; at most " +
                           std::to_string(kMaxSceneBytes) + " are kept");
  }
  return true;
}

double FrameTimeS(const v1::Envelope& e) {
  switch (e.body_case()) {
    case v1::Envelope::kDeviceSamples: {
      const auto& s = e.device_samples().samples();
      return s.empty() ? 0 : s[s.size() - 1].time_s();
    }
    case v1::Envelope::kMeshKeyframe:
      return e.mesh_keyframe().time_s();
    case v1::Envelope::kMeshDelta:
      return e.mesh_delta().time_s();
    case v1::Envelope::kTopologyEvent:
      return e.topology_event().time_s();
    case v1::Envelope::kSessionEvent:
      return e.session_event().time_s();
    case v1::Envelope::kAnnotation:
      return e.annotation().time_s();
    default:
      return 0;
  }
}

bool CheckAgentFrame(const v1::Envelope& e, std::string* error) {
  if (e.has_device_samples()) {
    // Every sample's time, not only the last one FrameTimeS gives.
    const v1::DeviceSamples& ds = e.device_samples();
    if (ds.samples_size() > kMaxSamplesPerBatch) {
      return Fail(error, "DeviceSamples has " + std::to_string(ds.samples_size()) + " samples; at most " +
                             std::to_string(kMaxSamplesPerBatch) + " a frame");
    }
    for (int i = 0; i < ds.samples_size(); ++i) {
      const v1::DeviceSample& s = ds.samples(i);
      const std::string where = "DeviceSamples.samples[" + std::to_string(i) + "]";
      if (s.tick() >= kMaxTick)
        return Fail(error, where + ".tick " + std::to_string(s.tick()) + " is at or above 2^63");
      if (!TimeOk(s.time_s())) return Fail(error, TimeError(where + ".time_s", s.time_s()));
      if (!VecOk(s.tool_pos()) || !VecOk(s.force())) return Fail(error, where + ": tool_pos and force must be finite");
      if (s.has_tool_orientation() && !QuatOk(s.tool_orientation()))
        return Fail(error, where + ".tool_orientation must be a finite unit quaternion");
      if (!std::isfinite(s.needle_inserted())) return Fail(error, where + ".needle_inserted must be finite");
    }
    return true;
  }
  // The other frames' one time, whichever field carries it.
  if (const double t_s = FrameTimeS(e); !TimeOk(t_s)) {
    return Fail(error, TimeError(std::string(EnvelopeBodyName(e)) + ".time_s", t_s));
  }
  switch (e.body_case()) {
    case v1::Envelope::kTopologyEvent:
      if (e.topology_event().atoms_size() > kMaxSamplesPerBatch) {
        return Fail(error, "TopologyEvent lists too many atoms");
      }
      return true;
    case v1::Envelope::kSessionEvent: {
      const v1::SessionEvent& s = e.session_event();
      if (s.tick() >= kMaxTick) return Fail(error, "SessionEvent.tick is at or above 2^63");
      if (!SizeOk(s.message(), kMaxEventTextBytes, "SessionEvent.message", error)) return false;
      return SizeOk(s.peer(), kMaxIdentityBytes, "SessionEvent.peer", error);
    }
    default:
      return true;  // the session says what it does not expect
  }
}

bool CheckPlaybackControl(const v1::PlaybackControl& c, std::string* error) {
  if (!v1::PlaybackControl::Action_IsValid(c.action()) || c.action() == v1::PlaybackControl::ACTION_UNSPECIFIED) {
    return Fail(error, "PlaybackControl.action " + std::to_string(c.action()) + " is not an action");
  }
  if (!std::isfinite(c.seek_time_s())) return Fail(error, "PlaybackControl.seek_time_s must be finite");
  if (!std::isfinite(c.speed())) return Fail(error, "PlaybackControl.speed must be finite");
  return true;
}

bool CheckAnnotation(const v1::Annotation& note, std::string* error) {
  if (note.text().empty() || note.text().size() > kMaxAnnotationBytes) {
    return Fail(error, "an annotation's text must have 1 to 1000 bytes");
  }
  if (!TimeOk(note.time_s())) return Fail(error, TimeError("Annotation.time_s", note.time_s()));
  return true;
}

}  // namespace idms::server
