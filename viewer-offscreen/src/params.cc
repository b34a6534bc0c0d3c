// Parsers of --size, --camera and seconds: exact (std::from_chars, the whole text, no locale).
#include "idms/render/params.h"

#include <charconv>
#include <cmath>

namespace idms::render {
namespace {

// A number that is the whole of `text`.
template <class T>
bool Number(std::string_view text, T* out) {
  if (text.empty() || text.front() == '+') return false;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), *out);
  return ec == std::errc() && end == text.data() + text.size();
}

// Three finite numbers "A,B,C".
bool Triple(std::string_view text, std::array<double, 3>* out) {
  std::array<double, 3> v{};
  for (int i = 0; i < 3; ++i) {
    const size_t comma = i < 2 ? text.find(',') : text.size();
    if (comma == std::string_view::npos || !Number(text.substr(0, comma), &v[i]) || !std::isfinite(v[i])) return false;
    text = i < 2 ? text.substr(comma + 1) : std::string_view();
  }
  *out = v;
  return true;
}

}  // namespace

bool ParseSize(std::string_view text, int* width, int* height, std::string* error) {
  const size_t x = text.find('x');
  int w = 0, h = 0;
  if (x == std::string_view::npos || !Number(text.substr(0, x), &w) || !Number(text.substr(x + 1), &h)) {
    *error = "size '" + std::string(text.substr(0, 64)) + "': expected WIDTHxHEIGHT in pixels, e.g. 1280x720";
    return false;
  }
  if (w < kMinSize || h < kMinSize || w > kMaxSize || h > kMaxSize || static_cast<int64_t>(w) * h > kMaxPixels) {
    *error = "size " + std::to_string(w) + "x" + std::to_string(h) + " is out of range: each side within " +
             std::to_string(kMinSize) + ".." + std::to_string(kMaxSize) + " and at most " + std::to_string(kMaxPixels) +
             " pixels (3840x2160)";
    return false;
  }
  *width = w;
  *height = h;
  return true;
}

bool ParseCamera(std::string_view text, Camera* camera, std::string* error) {
  if (text == "auto") {
    *camera = Camera{};
    return true;
  }
  const size_t colon = text.find(':');
  Camera c;
  c.automatic = false;
  if (colon == std::string_view::npos || !Triple(text.substr(0, colon), &c.eye) ||
      !Triple(text.substr(colon + 1), &c.target)) {
    *error = "camera '" + std::string(text.substr(0, 64)) +
             "': expected auto or EYE_X,EYE_Y,EYE_Z:TARGET_X,TARGET_Y,TARGET_Z (model units)";
    return false;
  }
  if (c.eye == c.target) {
    *error = "camera: the eye and the target must differ";
    return false;
  }
  *camera = c;
  return true;
}

bool ParseSeconds(std::string_view text, double* seconds, std::string* error) {
  double s = 0;
  if (!Number(text, &s) || !std::isfinite(s) || s < 0) {
    *error = "'" + std::string(text.substr(0, 64)) + "': expected a number of seconds >= 0";
    return false;
  }
  *seconds = s;
  return true;
}

}  // namespace idms::render
