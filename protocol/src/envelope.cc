// Envelope framing: size limit, protobuf parse, and a body required.
#include "idms/protocol/envelope.h"

#include <limits>
#include <string>

namespace idms {

bool ParseEnvelope(std::string_view bytes, v1::Envelope* out, std::string* error, int64_t max_bytes) {
  if (static_cast<int64_t>(bytes.size()) > max_bytes ||
      bytes.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    if (error != nullptr) {
      *error = "frame of " + std::to_string(bytes.size()) + " bytes exceeds the limit of " + std::to_string(max_bytes);
    }
    return false;
  }
  // ParseFromArray takes an int size; the check above keeps it in range.
  if (!out->ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    if (error != nullptr) {
      *error =
          "frame of " + std::to_string(bytes.size()) + " bytes is not a valid idms.v1.Envelope (protobuf parse failed)";
    }
    out->Clear();
    return false;
  }
  if (out->body_case() == v1::Envelope::BODY_NOT_SET) {
    if (error != nullptr) *error = "envelope has no body (or only one this version does not know)";
    return false;
  }
  return true;
}

bool ParseFrames(std::string_view bytes, std::vector<v1::Envelope>* out, std::string* error, int64_t max_bytes) {
  v1::Envelope e;
  if (!ParseEnvelope(bytes, &e, error, max_bytes)) return false;
  if (!e.has_frames()) {
    out->push_back(std::move(e));
    return true;
  }
  const auto& inner = e.frames().envelopes();
  if (inner.empty()) {
    if (error != nullptr) *error = "a Frames with no envelope";
    return false;
  }
  for (int i = 0; i < inner.size(); ++i) {
    v1::Envelope& one = out->emplace_back();
    std::string why;
    if (!ParseEnvelope(inner[i], &one, &why, max_bytes) || one.has_frames()) {
      out->pop_back();
      if (error != nullptr) {
        *error = "frames[" + std::to_string(i) + "]: " + (why.empty() ? "a Frames inside a Frames" : why);
      }
      return false;
    }
  }
  return true;
}

void SerializeEnvelope(const v1::Envelope& envelope, std::string* out) {
  out->clear();
  envelope.AppendToString(out);
}

const char* EnvelopeBodyName(const v1::Envelope& envelope) {
  switch (envelope.body_case()) {
    case v1::Envelope::kHello:
      return "hello";
    case v1::Envelope::kWelcome:
      return "welcome";
    case v1::Envelope::kDeviceSamples:
      return "device_samples";
    case v1::Envelope::kMeshKeyframe:
      return "mesh_keyframe";
    case v1::Envelope::kMeshDelta:
      return "mesh_delta";
    case v1::Envelope::kTopologyEvent:
      return "topology_event";
    case v1::Envelope::kSessionEvent:
      return "session_event";
    case v1::Envelope::kPlaybackControl:
      return "playback_control";
    case v1::Envelope::kPlaybackState:
      return "playback_state";
    case v1::Envelope::kCommand:
      return "command";
    case v1::Envelope::kAnnotation:
      return "annotation";
    case v1::Envelope::kAck:
      return "ack";
    case v1::Envelope::kFrames:
      return "frames";
    case v1::Envelope::BODY_NOT_SET:
      return "none";
  }
  return "unknown";
}

}  // namespace idms
