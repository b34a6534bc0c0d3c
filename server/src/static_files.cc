// The web viewer's built files (--web-root, built from viewer-web/): every page URL gets
// index.html (the viewer routes in the browser), /assets/* their files, each with its
// Content-Type and an ETag so that a browser revalidates for the price of a stat; streamed from
// the file, never held whole.
#include <sys/stat.h>

#include <cctype>
#include <sstream>

#include "idms/server/api.h"

namespace idms::server {
namespace {

// Asset names the build writes: letters, digits, '.', '_', '-'; never hidden, never a path.
bool SafeAssetName(const std::string& name) {
  if (name.empty() || name.size() > 128 || name.front() == '.') return false;
  for (const char c : name)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '_' && c != '-') return false;
  return true;
}

std::string ContentType(const std::string& name) {
  static const std::pair<const char*, const char*> kTypes[] = {
      {".html", "text/html; charset=utf-8"},
      {".js", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"},
      {".map", "application/json"},
      {".json", "application/json"},
      {".txt", "text/plain; charset=utf-8"},
      {".svg", "image/svg+xml"},
      {".png", "image/png"},
      {".ico", "image/x-icon"},
      {".woff2", "font/woff2"},
  };
  for (const auto& [ext, type] : kTypes) {
    const std::string e = ext;
    if (name.size() >= e.size() && name.compare(name.size() - e.size(), e.size(), e) == 0) return type;
  }
  return "application/octet-stream";
}

// Serves one file, streamed (FileRangeBody): 304 when the browser's ETag (size and modification
// time) still holds. Opened first, then fstat: the size sent is the size of the file opened.
HandlerResponse ServeFile(ApiContext& ctx, ApiRequest& req, const std::string& name, bool page) {
  if (ctx.options->web_root.empty())
    return JsonError(req, http::status::service_unavailable, "this server serves no web viewer (no --web-root)");
  const std::string path = ctx.options->web_root + "/" + name;
  boost::beast::file file;
  boost::beast::error_code ec;
  file.open(path.c_str(), boost::beast::file_mode::scan, ec);
  struct stat st {};
  if (ec || ::fstat(file.native_handle(), &st) != 0 || !S_ISREG(st.st_mode)) {
    if (page)
      return JsonError(req, http::status::service_unavailable,
                       "the web viewer is not built: " + path +
                           " is missing (scripts/build.sh builds it; --web-root names another directory)");
    return JsonError(req, http::status::not_found, "no such file: /" + name);
  }
  std::ostringstream tag;
  tag << '"' << std::hex << st.st_size << '-' << (st.st_mtim.tv_sec * 1000000000LL + st.st_mtim.tv_nsec) << '"';
  auto set_headers = [&](auto& res) {
    res.set(http::field::etag, tag.str());
    // Revalidate every time: file names carry no hash, and a stat is cheap.
    res.set(http::field::cache_control, "no-cache");
    res.set("X-Content-Type-Options", "nosniff");
    if (page) {
      res.set("Content-Security-Policy",
              "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; connect-src 'self'; "
              "frame-ancestors 'none'");
    }
  };
  if (Sv(req.message[http::field::if_none_match]) == tag.str()) {
    ApiResponse res{http::status::not_modified, req.message.version()};
    set_headers(res);
    return res;
  }
  FileResponse res{http::status::ok, req.message.version()};
  set_headers(res);
  res.set(http::field::content_type, ContentType(name));
  res.body().file = std::move(file);
  res.body().length = static_cast<uint64_t>(st.st_size);
  return res;
}

HandlerResponse ServePage(ApiContext& ctx, ApiRequest& req) { return ServeFile(ctx, req, "index.html", true); }

HandlerResponse ServeAsset(ApiContext& ctx, ApiRequest& req) {
  if (!SafeAssetName(req.params[0])) return JsonError(req, http::status::not_found, "no such file: " + req.path);
  return ServeFile(ctx, req, "assets/" + req.params[0], false);
}

}  // namespace

void AppendViewerRoutes(std::vector<Route>* routes) {
  using V = http::verb;
  // The viewer's own URLs (viewer-web/src/main.js); the page asks for a login itself.
  for (const char* pattern : {"/", "/login", "/sessions", "/session/{id}", "/replay/{id}", "/compare/{a}/{b}",
                              "/report/{id}", "/fit/{id}", "/trainee/{name}", "/models", "/models/{name}"})
    routes->push_back({V::get, pattern, std::nullopt, false, false, ServePage, true});
  routes->push_back({V::get, "/assets/{file}", std::nullopt, false, false, ServeAsset, true});
}

}  // namespace idms::server
