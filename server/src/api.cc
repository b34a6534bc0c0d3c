// The route table, admission (target, auth, role, Origin, size) and the small handlers: health,
// metrics, login, logout, whoami.
#include "idms/server/api.h"

#include <algorithm>
#include <boost/beast/websocket/rfc6455.hpp>
#include <charconv>
#include <nlohmann/json.hpp>

#include "idms/server/http_parse.h"
#include "idms/server/log.h"
#include "idms/server/storage.h"

namespace idms::server {
namespace {

using json = nlohmann::json;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// Matches "/api/models/{name}" against a path, capturing the {...} segments.
bool MatchPattern(const std::string& pattern, const std::string& path, std::vector<std::string>* params) {
  const std::vector<std::string_view> p = PathSegments(pattern), s = PathSegments(path);
  if (p.size() != s.size() || (path.size() > 1 && path.back() == '/')) return false;
  std::vector<std::string> captured;
  for (size_t i = 0; i < p.size(); ++i) {
    if (p[i].size() > 2 && p[i].front() == '{') {
      captured.emplace_back(s[i]);
    } else if (p[i] != s[i]) {
      return false;
    }
  }
  *params = std::move(captured);
  return true;
}

// The server's own origin as a browser writes it, from the Host header.
std::string OwnOrigin(const ApiRequest& req) {
  return std::string(req.tls ? "https://" : "http://") + Lower(std::string(req.message[http::field::host]));
}

bool OriginAllowed(const ApiContext& ctx, const ApiRequest& req, std::string_view origin) {
  std::string o = Lower(std::string(origin));
  while (!o.empty() && o.back() == '/') o.pop_back();
  if (o == OwnOrigin(req)) return true;
  for (std::string allowed : ctx.options->allowed_origins) {
    allowed = Lower(allowed);
    while (!allowed.empty() && allowed.back() == '/') allowed.pop_back();
    if (o == allowed) return true;
  }
  return false;
}

// The announced Content-Length (not payload_size(), which is the body's size: empty before it is read).
std::optional<uint64_t> ContentLength(const ApiRequest& req) {
  const auto it = req.message.find(http::field::content_length);
  if (it == req.message.end()) return std::nullopt;
  uint64_t n = 0;
  const std::string_view v = Sv(it->value());
  const auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
  if (ec != std::errc() || end != v.data() + v.size()) return std::nullopt;
  return n;
}

bool IsSafeMethod(http::verb v) { return v == http::verb::get || v == http::verb::head || v == http::verb::options; }

ApiResponse Health(ApiContext& ctx, ApiRequest& req) {
  const double uptime = std::chrono::duration<double>(std::chrono::steady_clock::now() - ctx.started).count();
  return JsonResponse(req, http::status::ok,
                      JsonText(json{{"status", "ok"}, {"version", ctx.version}, {"uptime_s", uptime}}));
}

ApiResponse MetricsText(ApiContext& ctx, ApiRequest& req) {
  const double uptime = std::chrono::duration<double>(std::chrono::steady_clock::now() - ctx.started).count();
  ApiResponse res{http::status::ok, req.message.version()};
  res.set(http::field::content_type, "text/plain; version=0.0.4; charset=utf-8");
  // The library's figures need the store; live figures do not, so /metrics still answers while
  // the database is down (the library's as 0, and idms_store_available 0 says why).
  int64_t models = 0, library_bytes = 0;
  bool store_available = true;
  try {
    models = ctx.library->models().NumModels();
    library_bytes = ctx.library->models().LibraryBytes();
  } catch (const StoreUnavailable&) {
    store_available = false;
  }
  res.body() = ctx.metrics->Render(models, library_bytes, uptime);
  res.body() +=
      "# HELP idms_store_available Whether the model and session stores answered (0: database down)\n"
      "# TYPE idms_store_available gauge\nidms_store_available " +
      std::string(store_available ? "1" : "0") + "\n";
  if (ctx.more_metrics) res.body() += ctx.more_metrics();
  return res;
}

ApiResponse Login(ApiContext& ctx, ApiRequest& req) {
  std::string token;
  try {
    const json body = json::parse(req.message.body());
    token = body.at("token").get<std::string>();
  } catch (const std::exception&) {
    return JsonError(req, http::status::bad_request, "expected a JSON body {\"token\": \"...\"}");
  }
  const Digest digest = DigestOf(token);
  const Role role = ctx.tokens()->LookupDigest(digest);
  if (role == Role::kNone) return JsonError(req, http::status::unauthorized, "unknown token");
  const std::string cookie = ctx.logins->Create(digest);
  ApiResponse res = JsonResponse(req, http::status::ok, JsonText(json{{"role", RoleName(role)}}));
  res.set(http::field::set_cookie, std::string(kSessionCookie) + "=" + cookie +
                                       "; Path=/; HttpOnly; SameSite=Strict; Max-Age=" +
                                       std::to_string(ctx.logins->lifetime().count()) + (req.tls ? "; Secure" : ""));
  return res;
}

ApiResponse Logout(ApiContext& ctx, ApiRequest& req) {
  if (const auto cookie = CookieValue(Sv(req.message[http::field::cookie]), kSessionCookie))
    ctx.logins->Remove(*cookie);
  ApiResponse res = JsonResponse(req, http::status::ok, JsonText(json{{"logged_out", true}}));
  res.set(http::field::set_cookie, std::string(kSessionCookie) + "=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0" +
                                       (req.tls ? "; Secure" : ""));
  return res;
}

ApiResponse WhoAmI(ApiContext&, ApiRequest& req) {
  return JsonResponse(req, http::status::ok,
                      JsonText(json{{"role", RoleName(req.role)}, {"via", req.via_cookie ? "cookie" : "token"}}));
}

}  // namespace

std::string JsonText(const json& j) { return j.dump(-1, ' ', false, json::error_handler_t::replace); }

ApiResponse JsonResponse(const ApiRequest& req, http::status status, const std::string& json_text) {
  ApiResponse res{status, req.message.version()};
  res.set(http::field::content_type, "application/json");
  res.set(http::field::cache_control, "no-store");
  res.body() = json_text;
  return res;
}

ApiResponse JsonError(const ApiRequest& req, http::status status, const std::string& message) {
  return JsonResponse(req, status, JsonText(json{{"error", message}}));
}

namespace {

// A browser that asks for a page that does not exist gets a page saying so, with the way back;
// API clients (no text/html in Accept, or an /api/ or /ws/ path) get the JSON error.
bool WantsPage(const ApiRequest& req) {
  const auto accept = req.message.find(http::field::accept);
  const bool html = accept != req.message.end() && Sv(accept->value()).find("text/html") != std::string_view::npos;
  const bool get = req.message.method() == http::verb::get || req.message.method() == http::verb::head;
  return html && get && req.path.rfind("/api/", 0) != 0 && req.path.rfind("/ws/", 0) != 0;
}

std::string HtmlEscaped(std::string_view text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '&':
        out += "&amp;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

ApiResponse NotFoundPage(const ApiRequest& req) {
  ApiResponse res{http::status::not_found, req.message.version()};
  res.set(http::field::content_type, "text/html; charset=utf-8");
  res.set(http::field::cache_control, "no-store");
  res.body() =
      "<!doctype html><html lang=\"en\"><meta charset=\"utf-8\"><meta name=\"viewport\" "
      "content=\"width=device-width\"><title>Not found - idms</title><body style=\"font: 16px system-ui; "
      "margin: 3em auto; max-width: 40em\"><h1>No page here</h1><p>There is no page at <code>" +
      HtmlEscaped(req.path) + "</code>.</p><p><a href=\"/\">Go to the sessions</a></p></body></html>\n";
  return res;
}

}  // namespace

std::vector<Route> MakeRoutes() {
  using P = Permission;
  using V = http::verb;
  std::vector<Route> routes = {
      {V::get, "/api/health", std::nullopt, false, false, Health},
      {V::post, "/api/login", std::nullopt, false, false, Login},
      {V::post, "/api/logout", P::kRead, false, false, Logout},
      {V::get, "/api/whoami", P::kRead, false, false, WhoAmI},
      {V::get, "/metrics", P::kRead, false, false, MetricsText},
      {V::get, "/api/models", P::kRead, false, false, ListModels},
      {V::get, "/api/models/{name}", P::kRead, false, false, GetModel},
      {V::put, "/api/models/{name}", P::kWrite, true, false, PutModel, true},
      {V::delete_, "/api/models/{name}", P::kWrite, false, false, DeleteModel, true},
      {V::get, "/api/models/{name}/{file}", P::kRead, false, false, GetModelFile, true},
  };
  AppendViewerRoutes(&routes);  // the web viewer's pages and assets (static_files.cc)
  return routes;
}

std::string_view MethodLabel(const std::vector<Route>& routes, http::verb method) {
  if (method == http::verb::unknown) return "other";
  const http::verb served = method == http::verb::head ? http::verb::get : method;
  for (const Route& r : routes) {
    if (r.method == served) return Sv(http::to_string(method));
  }
  return "other";
}

Admission Admit(ApiContext& ctx, const std::vector<Route>& routes, ApiRequest& req) {
  Admission a;
  auto fail = [&](http::status status, const std::string& message) {
    a.error = JsonError(req, status, message);
    return a;
  };
  // RFC 9112 3.2: an HTTP/1.1 request names exactly one Host, any request at most one, well formed.
  const size_t hosts = req.message.count(http::field::host);
  if (hosts > 1) return fail(http::status::bad_request, "more than one Host header");
  if (hosts == 0 && req.message.version() >= 11)
    return fail(http::status::bad_request, "an HTTP/1.1 request must carry a Host header");
  if (hosts == 1 && !ValidHost(Sv(req.message[http::field::host])))
    return fail(http::status::bad_request, "malformed Host header");
  // Target and route.
  if (!ParseTarget(Sv(req.message.target()), &req.path, &req.query))
    return fail(http::status::bad_request, "malformed request target");
  bool path_known = false;
  std::string allow;
  for (const Route& r : routes) {
    std::vector<std::string> params;
    if (!MatchPattern(r.pattern, req.path, &params)) continue;
    path_known = true;
    allow += (allow.empty() ? "" : ", ") + std::string(http::to_string(r.method));
    // HEAD is GET without the body (the connection drops it).
    const bool head_of_get = r.method == http::verb::get && req.message.method() == http::verb::head && !r.websocket;
    if (r.method != req.message.method() && !head_of_get) continue;
    a.route = &r;
    req.params = std::move(params);
    break;
  }
  if (a.route == nullptr) {
    if (!path_known && WantsPage(req)) {
      a.error = NotFoundPage(req);
      return a;
    }
    if (!path_known) return fail(http::status::not_found, "no such resource: " + req.path);
    fail(http::status::method_not_allowed,
         std::string(req.message.method_string()) + " is not allowed on " + req.path + " (allowed: " + allow + ")");
    a.error->set(http::field::allow, allow);
    return a;
  }
  const Route& route = *a.route;
  const bool upgrade = boost::beast::websocket::is_upgrade(req.message);
  if (route.websocket != upgrade)
    return fail(http::status::bad_request,
                route.websocket ? req.path + " is a WebSocket endpoint" : req.path + " does not speak WebSocket");
  // Authentication: a bearer token, else the login cookie.
  const std::shared_ptr<const TokenTable> tokens = ctx.tokens();
  const auto authorization = req.message.find(http::field::authorization);
  if (authorization != req.message.end()) {
    const auto token = BearerToken(Sv(authorization->value()));
    if (!token) return fail(http::status::unauthorized, "Authorization must be 'Bearer TOKEN'");
    req.token_digest = DigestOf(*token);
    req.role = tokens->LookupDigest(req.token_digest);
    if (req.role == Role::kNone) return fail(http::status::unauthorized, "unknown token");
  } else if (const auto cookie = CookieValue(Sv(req.message[http::field::cookie]), kSessionCookie)) {
    std::optional<Digest> digest;
    try {
      digest = ctx.logins->Find(*cookie);
    } catch (const StoreUnavailable& e) {
      a.error = StoreUnavailableResponse(req, e.what());
      return a;
    }
    if (digest) {
      req.token_digest = *digest;
      req.role = tokens->LookupDigest(*digest);  // kNone once the token left the file
      req.via_cookie = req.role != Role::kNone;
    }
  }
  if (route.permission) {
    if (req.role == Role::kNone)
      return fail(http::status::unauthorized,
                  "missing or expired credentials: send 'Authorization: Bearer TOKEN' "
                  "or log in with POST /api/login");
    if (!Allows(req.role, *route.permission))
      return fail(http::status::forbidden, std::string("role ") + RoleName(req.role) + " may not " +
                                               std::string(req.message.method_string()) + " " + route.pattern);
  }
  // Origin: cookie-authenticated writes, the login itself, and every upgrade that carries one.
  const auto origin = req.message.find(http::field::origin);
  const bool needs_origin = (req.via_cookie && !IsSafeMethod(req.message.method())) || route.pattern == "/api/login";
  if (origin != req.message.end() && (needs_origin || upgrade) && !OriginAllowed(ctx, req, Sv(origin->value())))
    return fail(http::status::forbidden, "origin " + std::string(origin->value()) + " is not allowed");
  if (origin == req.message.end() && req.via_cookie && !IsSafeMethod(req.message.method()))
    return fail(http::status::forbidden,
                "a cookie-authenticated " + std::string(req.message.method_string()) + " must carry an Origin header");
  // Size, before any of the body is read.
  a.body_limit =
      static_cast<uint64_t>(route.upload ? ctx.options->max_upload_bytes : ctx.options->max_small_body_bytes);
  if (const auto length = ContentLength(req); length && *length > a.body_limit)
    return fail(http::status::payload_too_large, "body of " + std::to_string(*length) + " bytes exceeds the limit of " +
                                                     std::to_string(a.body_limit) + " bytes");
  if (route.upload) {
    MediaType type;
    const auto ct = req.message.find(http::field::content_type);
    if (ct == req.message.end() || !ParseMediaType(Sv(ct->value()), &type) ||
        (type.type != "application/json" && type.type != "multipart/form-data"))
      return fail(http::status::unsupported_media_type,
                  "upload as application/json {\"fem\", \"plg\", \"description\"} or as multipart/form-data with "
                  "parts fem, plg, description");
  }
  return a;
}

ApiResponse StoreUnavailableResponse(const ApiRequest& req, const std::string& what) {
  Log(LogLevel::kWarn, "store unavailable", {{"path", req.path}, {"error", what}});
  ApiResponse res =
      JsonError(req, http::status::service_unavailable,
                "a store (the database or the object storage) is unavailable; retry shortly (live sessions are not "
                "affected)");
  res.set(http::field::retry_after, "1");
  return res;
}

void AnswerStoreFailures(std::vector<Route>* routes, bool stores_remote) {
  for (Route& r : *routes) {
    if (r.handler) {
      r.handler = [h = std::move(r.handler)](ApiContext& ctx, ApiRequest& req) -> HandlerResponse {
        try {
          return h(ctx, req);
        } catch (const StoreUnavailable& e) {
          return StoreUnavailableResponse(req, e.what());
        }
      };
      // A remote store's round trips (or its connection timeout) wait on a worker, not on an
      // I/O thread. The health check and the viewer's files never touch a store.
      const bool api = r.pattern.rfind("/api/", 0) == 0 || r.pattern == "/metrics";
      if (stores_remote && api && r.pattern != "/api/health") r.blocking = true;
    }
    if (r.open_websocket) {
      r.open_websocket = [open = std::move(r.open_websocket)](const ApiRequest& req,
                                                              std::string* refusal) -> std::shared_ptr<WsEndpoint> {
        try {
          return open(req, refusal);
        } catch (const StoreUnavailable& e) {
          *refusal = std::string("a store is unavailable; retry shortly: ") + e.what();
          return nullptr;
        }
      };
    }
  }
}

}  // namespace idms::server
