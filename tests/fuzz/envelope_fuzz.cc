// libFuzzer target: Envelope parsing and MeshMirror must reject any input cleanly, never crash,
// over-allocate or half-apply. The input is tried whole as one frame, then as a session: records
// of [uint16 little-endian length][Envelope bytes] applied in order to one mirror, so that
// mutated deltas meet a real keyframe state (the seeds are real sessions in this form).
#include <google/protobuf/stubs/logging.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_mirror.h"

namespace {

// Small enough to keep every input fast, large enough for the seeds.
idms::DecodeLimits FuzzLimits() {
  idms::DecodeLimits limits;
  limits.max_vertices = 1 << 16;
  limits.max_triangles = 1 << 17;
  limits.max_decompressed_bytes = 1 << 22;
  return limits;
}

constexpr int64_t kMaxFrameBytes = 1 << 20;

// After a successful apply the mirror must re-encode to a keyframe that decodes to itself.
void CheckMirrorConsistent(idms::MeshMirror& mirror) {
  idms::v1::MeshKeyframe key;
  std::string error;
  if (!mirror.MakeKeyframe(&key, &error)) __builtin_trap();
  idms::MeshMirror copy(FuzzLimits());
  if (copy.Apply(key, &error) != idms::MirrorStatus::kOk) __builtin_trap();
  const auto a = mirror.quantized();
  const auto b = copy.quantized();
  if (a.size() != b.size() || !std::equal(a.begin(), a.end(), b.begin())) __builtin_trap();
  if (mirror.positions().size() != a.size()) __builtin_trap();
}

void ApplyOne(const idms::v1::Envelope& env, idms::MeshMirror& mirror) {
  if (!env.has_mesh_keyframe() && !env.has_mesh_delta()) return;
  std::string error;
  const uint64_t sequence_before = mirror.sequence();
  const idms::MirrorStatus status = mirror.Apply(env, &error);
  if (status == idms::MirrorStatus::kOk) {
    CheckMirrorConsistent(mirror);
  } else {
    if (error.empty()) __builtin_trap();
    if (mirror.sequence() != sequence_before) __builtin_trap();  // rejected frames change nothing
  }
}

// One WebSocket message as a viewer reads it: an envelope, or a Frames of them (ParseFrames).
void ApplyFrame(std::string_view bytes, idms::MeshMirror& mirror) {
  std::vector<idms::v1::Envelope> frames;
  std::string error;
  if (!idms::ParseFrames(bytes, &frames, &error, kMaxFrameBytes)) {
    if (error.empty()) __builtin_trap();  // every rejection says why
    return;
  }
  if (frames.empty()) __builtin_trap();
  for (const idms::v1::Envelope& env : frames) {
    if (env.has_frames()) __builtin_trap();  // never nested
    ApplyOne(env, mirror);
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // Protobuf logs invalid UTF-8 in strings; that is expected here.
  google::protobuf::SetLogHandler(nullptr);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  // The whole input as one frame.
  {
    idms::MeshMirror mirror(FuzzLimits());
    ApplyFrame(input, mirror);
  }
  // The input as a session of length-prefixed frames.
  idms::MeshMirror mirror(FuzzLimits());
  size_t at = 0;
  while (at + 2 <= size) {
    const size_t len = static_cast<size_t>(data[at]) | (static_cast<size_t>(data[at + 1]) << 8);
    at += 2;
    const size_t n = len < size - at ? len : size - at;
    ApplyFrame(input.substr(at, n), mirror);
    at += n;
  }
  return 0;
}
