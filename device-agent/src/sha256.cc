// SHA-256 for the model cache's content addresses, from OpenSSL's libcrypto (EVP one-shot digest).
#include <openssl/evp.h>

#include <cstdio>
#include <string>
#include <string_view>

#include "idms/agent/model_source.h"

namespace idms::agent {

std::string Sha256Hex(std::string_view bytes) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  if (EVP_Digest(bytes.data(), bytes.size(), digest, &length, EVP_sha256(), nullptr) != 1) return {};
  std::string hex(2 * length, '0');
  for (unsigned int i = 0; i < length; ++i) std::snprintf(&hex[2 * i], 3, "%02x", digest[i]);
  return hex;
}

}  // namespace idms::agent
