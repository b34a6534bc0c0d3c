// Model download from the server's library (synchronous Beast HTTP, before the loop starts) and
// the content-addressed cache.
#include "idms/agent/model_source.h"

#include <unistd.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "text_internal.h"

namespace idms::agent {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace fs = std::filesystem;
using tcp = asio::ip::tcp;

// A transport failure (the server cannot be reached) as opposed to an HTTP refusal.
struct HttpResult {
  bool reached = false;
  unsigned status = 0;
  std::string body;
  std::string error;
};

HttpResult HttpGet(const ModelFetchOptions& o, const std::string& target) {
  HttpResult r;
  try {
    asio::io_context io;
    tcp::resolver resolver(io);
    beast::tcp_stream stream(io);
    const auto timeout = std::chrono::milliseconds(static_cast<int64_t>(o.timeout_s * 1000));
    stream.expires_after(timeout);
    stream.connect(resolver.resolve(o.host, o.port));
    http::request<http::empty_body> req{http::verb::get, target, 11};
    req.set(http::field::host, o.host + ":" + o.port);
    req.set(http::field::user_agent, "idms-agent");
    req.set(http::field::authorization, "Bearer " + o.token);
    http::write(stream, req);
    r.reached = true;
    beast::flat_buffer buffer;
    http::response_parser<http::string_body> parser;
    parser.body_limit(static_cast<uint64_t>(o.max_bytes));
    http::read(stream, buffer, parser);
    r.status = parser.get().result_int();
    r.body = std::move(parser.get().body());
    beast::error_code ignored;
    stream.socket().shutdown(tcp::socket::shutdown_both, ignored);
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  return r;
}

bool ReadFile(const fs::path& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  *out = ss.str();
  return static_cast<bool>(in) || in.eof();
}

// Through a temporary file and a rename, so a reader never sees half a file.
bool WriteFileAtomic(const fs::path& path, const std::string& bytes, std::string* error) {
  std::error_code ec;
  fs::create_directories(path.parent_path(), ec);
  const fs::path tmp = path.string() + ".tmp" + std::to_string(::getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) {
      *error = "cannot write " + tmp.string();
      return false;
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    *error = "cannot rename " + tmp.string() + " to " + path.string() + ": " + ec.message();
    return false;
  }
  return true;
}

bool IsHex64(const std::string& s) {
  return s.size() == 64 && s.find_first_not_of("0123456789abcdef") == std::string::npos;
}

// The blob for `sha`, downloaded from `target` when not cached (or cached but corrupt).
bool EnsureBlob(const ModelFetchOptions& o, const fs::path& cache, const std::string& sha, const std::string& target,
                std::string* path, std::string* error) {
  const fs::path blob = cache / "blobs" / sha;
  std::string bytes;
  if (ReadFile(blob, &bytes) && Sha256Hex(bytes) == sha) {
    *path = blob.string();
    return true;
  }
  const HttpResult r = HttpGet(o, target);
  if (r.status != 200) {
    *error = "GET " + target + ": " + (r.status != 0 ? "HTTP " + std::to_string(r.status) + " " + r.body : r.error);
    return false;
  }
  const std::string got = Sha256Hex(r.body);
  if (got != sha) {
    *error = "GET " + target + ": content hash " + got + " does not match the library's " + sha;
    return false;
  }
  if (!WriteFileAtomic(blob, r.body, error)) return false;
  *path = blob.string();
  return true;
}

}  // namespace

bool ParseModelName(std::string_view text, std::string* name, std::string* version, std::string* error) {
  const size_t at = text.find('@');
  const std::string_view n = text.substr(0, at);
  const std::string_view v = at == std::string_view::npos ? std::string_view() : text.substr(at + 1);
  const bool name_ok = !n.empty() && n.size() <= 128 && n.find("..") == std::string_view::npos &&
                       n.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_.-") ==
                           std::string_view::npos;
  const bool version_ok = at == std::string_view::npos ||
                          (!v.empty() && v.size() <= 9 && v.find_first_not_of("0123456789") == std::string_view::npos);
  if (!name_ok || !version_ok) {
    *error = Cat({"--model '", text}) +
             "': expected NAME or NAME@VERSION (NAME of letters, digits, '_', '.', '-'; VERSION digits)";
    return false;
  }
  *name = std::string(n);
  *version = std::string(v);
  return true;
}

std::string DefaultCacheDir() {
  if (const char* dir = std::getenv("IDMS_CACHE_DIR"); dir != nullptr && *dir != '\0') return dir;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg != '\0')
    return std::string(xdg) + "/idms";
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0')
    return std::string(home) + "/.cache/idms";
  return "/tmp/idms-cache";
}

bool FetchModel(std::string_view name_at_version, const ModelFetchOptions& o, std::string* fem_path,
                std::string* plg_path, std::string* error, bool* refused) {
  std::string name, version;
  if (!ParseModelName(name_at_version, &name, &version, error)) return false;
  const fs::path cache = o.cache_dir;
  const std::string query = version.empty() ? "" : "?version=" + version;
  const std::string base = "/api/models/" + name;
  const fs::path index = cache / "index" / (name + "@" + (version.empty() ? "latest" : version) + ".json");

  // Metadata from the server, or the cached index when the server cannot be reached.
  std::string meta_text;
  const HttpResult meta = HttpGet(o, base + query);
  if (meta.status == 200) {
    meta_text = meta.body;
  } else if (!meta.reached && ReadFile(index, &meta_text)) {
    std::fprintf(stderr, "idms-agent: the model library at %s:%s is unreachable (%s); using the cached %s\n",
                 o.host.c_str(), o.port.c_str(), meta.error.c_str(), index.string().c_str());
  } else if (meta.status == 401 || meta.status == 403) {
    if (refused != nullptr) *refused = true;
    *error = Cat({"model '", name_at_version}) + "': the server refused the token (HTTP " +
             std::to_string(meta.status) + " on GET " + base + query + "): check --token";
    return false;
  } else {
    *error = Cat({"model '", name_at_version}) + "': GET " + base + query + " on " + o.host + ":" + o.port + ": " +
             (meta.status != 0 ? "HTTP " + std::to_string(meta.status) + " " + meta.body.substr(0, 200)
                               : meta.error + " (and no cached copy in " + cache.string() + ")");
    return false;
  }
  // The two content hashes.
  std::string fem_sha, plg_sha;
  try {
    const nlohmann::json j = nlohmann::json::parse(meta_text);
    fem_sha = j.at("fem_sha256").get<std::string>();
    plg_sha = j.at("plg_sha256").get<std::string>();
  } catch (const std::exception& e) {
    *error = Cat({"model '", name_at_version}) + "': metadata from " + base + query +
             " is not {\"fem_sha256\": \"<64 hex>\", \"plg_sha256\": ...}: " + e.what();
    return false;
  }
  if (!IsHex64(fem_sha) || !IsHex64(plg_sha)) {
    *error = Cat({"model '", name_at_version}) + "': fem_sha256 and plg_sha256 must be 64 lowercase hex digits";
    return false;
  }
  // The files, by content address.
  if (!EnsureBlob(o, cache, fem_sha, base + "/fem" + query, fem_path, error) ||
      !EnsureBlob(o, cache, plg_sha, base + "/plg" + query, plg_path, error)) {
    *error = Cat({"model '", name_at_version}) + "': " + *error;
    return false;
  }
  if (meta.status == 200 && !WriteFileAtomic(index, meta_text, error)) return false;
  return true;
}

}  // namespace idms::agent
