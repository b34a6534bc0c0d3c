// Scene files: idms.v1.Scene in protobuf text format (models/*.scene). Loading reports a syntax
// error as FILE:LINE:COL: message and a bad value as FILE:LINE:COL: field: what was expected.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "idms/protocol/idms.pb.h"

namespace idms {

// Largest scene file read; a scene is a few hundred bytes.
inline constexpr int64_t kMaxSceneBytes = int64_t{1} << 20;

// Parses scene text (not validated). `file` names the source in errors. On failure *scene is
// unchanged and *error is "FILE:LINE:COL: message".
bool ParseSceneText(std::string_view text, std::string_view file, v1::Scene* scene, std::string* error);

// Checks values and names the first bad field: "tools[0].radius: must be > 0, got -1".
// Unset optional fields are fine (they take defaults); see idms.proto for each field's range.
bool ValidateScene(const v1::Scene& scene, std::string* error);

// Fills every unset optional field with its documented default (dt_s 0.001, stream_rate_hz 60,
// quant_step 1e-4, keyframe_interval_s 5, tool local_radius = radius, device scale 1, ...).
void ApplySceneDefaults(v1::Scene* scene);

// Reads, parses and validates a scene file, then applies defaults. Errors carry the file, and the
// line and column of the offending text or field. On failure *scene is unchanged.
bool LoadScene(const std::string& path, v1::Scene* scene, std::string* error);

// Parses and validates scene text the same way (for scenes sent in Hello or uploaded).
bool LoadSceneText(std::string_view text, std::string_view file, v1::Scene* scene, std::string* error);

}  // namespace idms
