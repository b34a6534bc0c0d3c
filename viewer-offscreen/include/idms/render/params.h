// The renderer's small text parameters (--size, --camera, ?size=): pure parsers, fuzzed
// (tests/fuzz/render_params_fuzz.cc), shared by idms-render and the server's endpoints.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

namespace idms::render {

// Where the camera is. automatic: looks at the surface's bounding sphere from above and in front
// (z up), framing all of it.
struct Camera {
  bool automatic = true;
  std::array<double, 3> eye{0, 0, 0};     // model units (when not automatic)
  std::array<double, 3> target{0, 0, 0};  // model units
};

inline constexpr int kMinSize = 16;
inline constexpr int kMaxSize = 4096;
inline constexpr int64_t kMaxPixels = int64_t{3840} * 2160;  // 4K: 33 MB of RGBA, the most one render holds

// "WxH", e.g. "1280x720": each within [kMinSize, kMaxSize], W*H <= kMaxPixels. On failure *error
// says what was expected and the outputs are unchanged.
bool ParseSize(std::string_view text, int* width, int* height, std::string* error);

// "auto", or "X,Y,Z:TX,TY,TZ" (eye, then the point looked at; model units; finite; eye != target).
bool ParseCamera(std::string_view text, Camera* camera, std::string* error);

// A finite, non-negative number of seconds, e.g. "1.5" (for --at, --every and ?t=).
bool ParseSeconds(std::string_view text, double* seconds, std::string* error);

}  // namespace idms::render
