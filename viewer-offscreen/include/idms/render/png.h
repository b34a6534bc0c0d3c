// PNG with libpng, tuned for speed: zlib level 1 and one filter (libpng's default adaptive
// filtering tries all five per row and costs more than the render itself).
#pragma once

#include <string>

#include "idms/render/render.h"

namespace idms::render {

// Encodes `image` as an 8-bit RGB PNG (alpha dropped) into *out (replaced). False with *error on
// a libpng failure.
bool EncodePng(const Image& image, std::string* out, std::string* error);

// Decodes a PNG into RGBA (for tests and tools). False with *error when it is not one.
bool DecodePng(const std::string& bytes, Image* out, std::string* error);

// Writes bytes to a file through a temporary name and a rename.
bool WriteFile(const std::string& path, const std::string& bytes, std::string* error);

}  // namespace idms::render
