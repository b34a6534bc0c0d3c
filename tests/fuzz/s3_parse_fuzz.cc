// libFuzzer target: what the S3 client reads from a store (ListObjectsV2 listings, <Error>
// replies) and from the command line (s3:// URLs) is rejected cleanly, never crashes or runs away.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "../../server/src/s3_client.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  idms::server::S3ListPage page;
  std::string error;
  if (idms::server::ParseListObjectsV2(text, &page, &error)) {
    if (page.truncated && page.next_token.empty()) __builtin_trap();  // a next page must be reachable
    for (const auto& o : page.objects) {
      if (o.key.size() > size) __builtin_trap();  // a key is never longer than the reply
    }
  } else if (error.empty()) {
    __builtin_trap();  // every rejection says why
  }
  // S3's code and message, each cut to its bound.
  if (idms::server::ParseS3Error(text).size() > 128 + 2 + 512) __builtin_trap();
  // A URL that parses describes itself as one that parses to the same place.
  idms::server::S3Location location, again;
  if (idms::server::ParseS3Url(std::string(text), &location, &error)) {
    if (!idms::server::ParseS3Url(location.Describe(), &again, &error) || again.host != location.host ||
        again.port != location.port || again.bucket != location.bucket)
      __builtin_trap();
  }
  return 0;
}
