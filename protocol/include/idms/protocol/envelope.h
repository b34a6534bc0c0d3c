// Framing: one WebSocket binary frame carries one idms.v1.Envelope. Parsing is the boundary where
// bytes from the network become messages; it rejects oversize, malformed and empty frames.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "idms/protocol/idms.pb.h"

namespace idms {

// Hello.protocol_version / Welcome.protocol_version of this build. Bumped on an incompatible
// change; additions that old readers can skip (new fields, new oneof members) keep it.
inline constexpr uint32_t kProtocolVersion = 1;

// Largest frame accepted by default: a keyframe of the 10^5-atom model is ~0.3 MB.
inline constexpr int64_t kDefaultMaxFrameBytes = int64_t{32} << 20;

// Parses one frame. Returns false with a message when the frame is larger than max_bytes, is not
// a valid Envelope, or has no body. Unknown fields (from a newer peer) are kept, not an error.
bool ParseEnvelope(std::string_view bytes, v1::Envelope* out, std::string* error,
                   int64_t max_bytes = kDefaultMaxFrameBytes);

// Parses one WebSocket message into the envelopes it carries: the envelope itself, or each of a
// Frames' envelopes in order (appended to *out). False with a message as ParseEnvelope, or when a
// Frames is empty or holds a malformed or nested Frames envelope.
bool ParseFrames(std::string_view bytes, std::vector<v1::Envelope>* out, std::string* error,
                 int64_t max_bytes = kDefaultMaxFrameBytes);

// Serializes one frame into *out (replacing its contents; reuse the string to avoid allocation).
void SerializeEnvelope(const v1::Envelope& envelope, std::string* out);

// The name of the body that is set ("mesh_delta", ...) or "none", for logs.
const char* EnvelopeBodyName(const v1::Envelope& envelope);

}  // namespace idms
