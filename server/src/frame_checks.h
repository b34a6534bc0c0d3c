// What the server checks at the door of its WebSockets before anything is stored, broadcast or
// recorded: sizes of every stored string, times that are finite and in range, tick numbers that
// cannot wrap. Pure functions of the message; the error says which field and what was expected.
#pragma once

#include <cstdint>
#include <string>

#include "idms/protocol/idms.pb.h"

namespace idms::server {

// Session times (s) outside [0, kMaxSessionTimeS] are refused: 10^7 s is 115 days, longer than
// any session; beyond it a duration would lose its meaning (and 1e300 overflows every clock).
inline constexpr double kMaxSessionTimeS = 1e7;
// Ticks at or above 2^63 are refused, so tick + 1 never wraps.
inline constexpr uint64_t kMaxTick = uint64_t{1} << 63;
inline constexpr size_t kMaxIdentityBytes = 256;     // Hello.identity, Hello.device
inline constexpr size_t kMaxSceneBytes = 64 << 10;   // Hello.scene, serialized
inline constexpr size_t kMaxEventTextBytes = 4096;   // SessionEvent.message from the agent
inline constexpr size_t kMaxAnnotationBytes = 1000;  // Annotation.text
inline constexpr int kMaxSamplesPerBatch = 10000;    // DeviceSamples.samples

// An agent's Hello: protocol version and role aside (the hub checks those), its strings and scene.
bool CheckAgentHello(const v1::Hello& hello, std::string* error);
// The session time a frame speaks of, s (DeviceSamples: its last sample's); 0 when it has none.
double FrameTimeS(const v1::Envelope& e);
// A frame an agent sends after its Hello: samples, mesh frames, events.
bool CheckAgentFrame(const v1::Envelope& e, std::string* error);
// A replay viewer's control: a known action, a finite seek time and speed (the replay clamps the
// time to the recording and checks the speed's range).
bool CheckPlaybackControl(const v1::PlaybackControl& c, std::string* error);
// A viewer's annotation: 1 to 1000 bytes of text, a time that is 0 (now) or a session time.
bool CheckAnnotation(const v1::Annotation& note, std::string* error);

}  // namespace idms::server
