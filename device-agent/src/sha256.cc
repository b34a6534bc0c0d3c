// SHA-256 (FIPS 180-4) for the model cache's content addresses. The round constants are derived
// at first use from their definition (fractional bits of the cube and square roots of the first
// primes) rather than typed in; tests check the standard vectors.
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "idms/agent/model_source.h"

namespace idms::agent {
namespace {

struct Constants {
  std::array<uint32_t, 64> k;  // cube roots of the first 64 primes
  std::array<uint32_t, 8> h0;  // square roots of the first 8 primes
};

// First 32 fractional bits of x.
uint32_t FractionBits(long double x) {
  const long double frac = x - std::floor(x);
  return static_cast<uint32_t>(std::floor(std::ldexp(frac, 32)));
}

Constants MakeConstants() {
  Constants c{};
  int found = 0;
  for (int n = 2; found < 64; ++n) {
    bool prime = true;
    for (int d = 2; d * d <= n; ++d) prime = prime && (n % d != 0);
    if (!prime) continue;
    c.k[static_cast<size_t>(found)] = FractionBits(std::cbrt(static_cast<long double>(n)));
    if (found < 8) c.h0[static_cast<size_t>(found)] = FractionBits(std::sqrt(static_cast<long double>(n)));
    ++found;
  }
  return c;
}

uint32_t Rotr(uint32_t x, int n) { return (x >> n) | (x << (32 - n)); }

// One 64-byte block into the state h.
void Compress(const Constants& c, const uint8_t* block, uint32_t h[8]) {
  uint32_t w[64];
  for (int i = 0; i < 16; ++i) {
    w[i] = static_cast<uint32_t>(block[4 * i]) << 24 | static_cast<uint32_t>(block[4 * i + 1]) << 16 |
           static_cast<uint32_t>(block[4 * i + 2]) << 8 | static_cast<uint32_t>(block[4 * i + 3]);
  }
  for (int i = 16; i < 64; ++i) {
    const uint32_t s0 = Rotr(w[i - 15], 7) ^ Rotr(w[i - 15], 18) ^ (w[i - 15] >> 3);
    const uint32_t s1 = Rotr(w[i - 2], 17) ^ Rotr(w[i - 2], 19) ^ (w[i - 2] >> 10);
    w[i] = w[i - 16] + s0 + w[i - 7] + s1;
  }
  uint32_t a = h[0], b = h[1], cc = h[2], d = h[3], e = h[4], f = h[5], g = h[6], hh = h[7];
  for (int i = 0; i < 64; ++i) {
    const uint32_t t1 =
        hh + (Rotr(e, 6) ^ Rotr(e, 11) ^ Rotr(e, 25)) + ((e & f) ^ (~e & g)) + c.k[static_cast<size_t>(i)] + w[i];
    const uint32_t t2 = (Rotr(a, 2) ^ Rotr(a, 13) ^ Rotr(a, 22)) + ((a & b) ^ (a & cc) ^ (b & cc));
    hh = g, g = f, f = e, e = d + t1, d = cc, cc = b, b = a, a = t1 + t2;
  }
  h[0] += a, h[1] += b, h[2] += cc, h[3] += d, h[4] += e, h[5] += f, h[6] += g, h[7] += hh;
}

}  // namespace

std::string Sha256Hex(std::string_view bytes) {
  static const Constants c = MakeConstants();
  uint32_t h[8];
  for (int i = 0; i < 8; ++i) h[i] = c.h0[static_cast<size_t>(i)];
  // Whole blocks, then the padded tail: 0x80, zeros, the bit length big-endian.
  size_t pos = 0;
  const auto* data = reinterpret_cast<const uint8_t*>(bytes.data());
  for (; pos + 64 <= bytes.size(); pos += 64) Compress(c, data + pos, h);
  uint8_t tail[128] = {};
  const size_t rest = bytes.size() - pos;
  for (size_t i = 0; i < rest; ++i) tail[i] = data[pos + i];
  tail[rest] = 0x80;
  const size_t tail_len = rest + 9 <= 64 ? 64 : 128;
  const uint64_t bits = static_cast<uint64_t>(bytes.size()) * 8;
  for (int i = 0; i < 8; ++i) tail[tail_len - 1 - static_cast<size_t>(i)] = static_cast<uint8_t>(bits >> (8 * i));
  for (size_t off = 0; off < tail_len; off += 64) Compress(c, tail + off, h);
  // Hex, big-endian words.
  static const char kHex[] = "0123456789abcdef";
  std::string out(64, '0');
  for (int i = 0; i < 8; ++i) {
    for (int j = 0; j < 8; ++j) out[static_cast<size_t>(8 * i + j)] = kHex[(h[i] >> (28 - 4 * j)) & 0xf];
  }
  return out;
}

}  // namespace idms::agent
