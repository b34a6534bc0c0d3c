// Hex and SHA-256, as the library's content addresses, ETags, resume tokens and token digests
// write them: lowercase hex digits, two per byte. One place for the server and the agent.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace idms {

// Each byte as two lowercase hex digits.
std::string HexEncode(std::span<const uint8_t> bytes);

// SHA-256 of bytes as 64 lowercase hex digits (FIPS 180-4, OpenSSL's libcrypto).
std::string Sha256Hex(std::string_view bytes);

}  // namespace idms
