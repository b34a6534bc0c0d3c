// Where the agent's model comes from: the server's model library over HTTP (cached on disk by
// content hash, so a model is downloaded once and an unreachable server can fall back to the
// cache), or a local file pair.
//
// URL scheme (the server implements it; tests/agent's endpoint does too):
//   GET /api/models/NAME[?version=V]      -> 200 application/json
//       {"name": "...", "version": N, "fem_sha256": "<64 hex>", "plg_sha256": "<64 hex>"}
//   GET /api/models/NAME/fem[?version=V]  -> 200 text/plain, the .fem file
//   GET /api/models/NAME/plg[?version=V]  -> 200 text/plain, the .plg file
// every request carrying "Authorization: Bearer TOKEN"; no version = the latest.
// Cache: DIR/blobs/<sha256> (verified on write and on use), DIR/index/NAME@V.json (the last
// metadata seen, V = "latest" when none was asked for).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "idms/protocol/digest.h"

namespace idms::agent {

struct ModelFetchOptions {
  std::string host, port;  // the server's HTTP address (the same port as its WebSocket)
  std::string token;
  std::string cache_dir;                   // created when missing
  double timeout_s = 30;                   // per request
  int64_t max_bytes = int64_t{512} << 20;  // per file
};

// Splits "NAME" or "NAME@VERSION"; NAME is [A-Za-z0-9_.-]+ without "..", VERSION digits.
bool ParseModelName(std::string_view text, std::string* name, std::string* version, std::string* error);

// Makes sure the model's .fem and .plg are in the cache and returns their paths. Downloads only
// files whose hash is not cached yet; when the server cannot be reached, uses the cached index
// (and says so on stderr). False with an actionable message otherwise; *refused (if given) is
// then true when the server refused the token (HTTP 401/403). Any thread but the loop's.
bool FetchModel(std::string_view name_at_version, const ModelFetchOptions& options, std::string* fem_path,
                std::string* plg_path, std::string* error, bool* refused = nullptr);

// The default cache directory: $IDMS_CACHE_DIR, else $XDG_CACHE_HOME/idms, else ~/.cache/idms.
std::string DefaultCacheDir();

using ::idms::Sha256Hex;  // idms/protocol/digest.h: SHA-256 as 64 lowercase hex digits

}  // namespace idms::agent
