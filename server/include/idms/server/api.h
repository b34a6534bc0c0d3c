// The HTTP API without sockets: a route table (pattern -> permission, body limit, handler), the
// admission of a request header (target, route, token or cookie, role, Origin, size) before any
// body is read, and handlers as plain functions from an admitted request to a response. The
// connection code (server.cc) calls Admit, reads the body, then runs the handler on a worker.
#pragma once

#include <boost/beast/http.hpp>
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "idms/server/auth.h"
#include "idms/server/file_body.h"
#include "idms/server/library.h"
#include "idms/server/metrics.h"
#include "idms/server/options.h"

namespace idms::server {

namespace http = boost::beast::http;

using ApiResponse = http::response<http::string_body>;
// A response streamed from a file (FileRangeBody): static files and recordings.
using FileResponse = http::response<FileRangeBody>;
// What a handler returns: a response held in memory, or one the connection sends from a file in
// pieces, so that memory per slow client is bounded by a piece, not by the file.
using HandlerResponse = std::variant<ApiResponse, FileResponse>;

// Beast 1.74's string_view is Boost's; ours is std's.
inline std::string_view Sv(boost::beast::string_view s) { return {s.data(), s.size()}; }

// Everything a handler may use. Owned by the server; shared by all connections.
struct ApiContext {
  const ServerOptions* options = nullptr;
  Library* library = nullptr;
  LoginSessions* logins = nullptr;
  Metrics* metrics = nullptr;
  std::function<std::shared_ptr<const TokenTable>()> tokens;  // the table in force
  std::function<void(std::string)> publish_library_event;     // a JSON text to /ws/library watchers
  std::function<std::string()> more_metrics;                  // Prometheus lines appended to /metrics (sessions)
  std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now();
  std::string version = "0.1.0";
};

struct ApiRequest {
  http::request<http::string_body> message;  // headers and (once read) body
  std::string path;                          // decoded, without the query
  std::map<std::string, std::string> query;
  std::vector<std::string> params;  // the route's {...} captures, in order
  Role role = Role::kNone;
  bool via_cookie = false;
  Digest token_digest{};
  bool tls = false;
  std::string peer;
};

using Handler = std::function<HandlerResponse(ApiContext&, ApiRequest&)>;

class WsEndpoint;  // server/src/ws_endpoint.h
// A WebSocket route's endpoint for an admitted upgrade; null with *refusal when there is nothing
// to connect to (an unknown session).
using WsOpener = std::function<std::shared_ptr<WsEndpoint>(const ApiRequest&, std::string* refusal)>;

struct Route {
  http::verb method;
  std::string pattern;                   // "/api/models/{name}/{file}"; also the metrics label
  std::optional<Permission> permission;  // nullopt: no token needed
  bool upload = false;                   // body up to --max-upload-mb, else the small limit
  bool websocket = false;                // a WebSocket upgrade (the connection code takes over)
  Handler handler;                       // empty for WebSocket routes
  // Runs on the worker pool: it parses, hashes, reads a file or waits for an fsync. Otherwise it
  // runs on the connection's strand (a few microseconds of SQLite read, no file I/O): a thread
  // hand-off costs more than such a handler.
  bool blocking = false;
  WsOpener open_websocket;  // WebSocket routes only
};

// The routes of this server, in match order.
std::vector<Route> MakeRoutes();

// The web viewer's routes (static_files.cc): its page URLs serve index.html, /assets/{file} the
// build's files, from ServerOptions::web_root; no token needed (the page asks for a login).
void AppendViewerRoutes(std::vector<Route>* routes);

// What admission decided: either a response to send at once (error set) or the route to run.
struct Admission {
  std::optional<ApiResponse> error;  // 4xx / 5xx, already complete
  const Route* route = nullptr;
  uint64_t body_limit = 0;
};

// Checks a request header: target, route and method, authentication (Bearer token, else the
// login cookie), permission, Origin (for cookie-authenticated writes and every WebSocket upgrade
// that carries one), Content-Length against the route's limit. Fills req's path, query, params,
// role. Pure apart from reading the token table and login sessions.
Admission Admit(ApiContext& ctx, const std::vector<Route>& routes, ApiRequest& req);

// The request's method as a metrics label: a verb some route takes (HEAD with GET), else
// "other". Methods are the client's to choose; a label per spelling would grow without bound.
std::string_view MethodLabel(const std::vector<Route>& routes, http::verb method);

// A JSON text for a response: bytes that are not UTF-8 (a client's path, a parser's quote of a
// file) are replaced, never thrown on.
std::string JsonText(const nlohmann::json& j);

// A JSON error response: {"error": message}.
ApiResponse JsonError(const ApiRequest& req, http::status status, const std::string& message);
ApiResponse JsonResponse(const ApiRequest& req, http::status status, const std::string& json_text);

// A model version as the API shows it (without its metadata): the GET's fields and the library
// events' "model".
nlohmann::json ModelVersionJson(const ModelVersion& v);
// {"event": "model_added", "model": ModelVersionJson(v)} to the /ws/library watchers.
void PublishModelAdded(ApiContext& ctx, const ModelVersion& v);
// Handlers of the model library (models_api.cc).
ApiResponse ListModels(ApiContext& ctx, ApiRequest& req);
ApiResponse GetModel(ApiContext& ctx, ApiRequest& req);
ApiResponse GetModelFile(ApiContext& ctx, ApiRequest& req);
ApiResponse PutModel(ApiContext& ctx, ApiRequest& req);
ApiResponse DeleteModel(ApiContext& ctx, ApiRequest& req);

// 503 with Retry-After: 1 and a JSON error: a store (the database) could not be reached.
ApiResponse StoreUnavailableResponse(const ApiRequest& req, const std::string& what);

// Wraps every handler of `routes` so that a StoreUnavailable it throws is answered with
// StoreUnavailableResponse instead of a 500, and every WebSocket opener so that it is refused
// with a reason. With `stores_remote` (PostgreSQL), every /api/ handler but the health check runs
// on the worker pool. Call once, after the whole table is built.
void AnswerStoreFailures(std::vector<Route>* routes, bool stores_remote);

// The login cookie's name.
inline constexpr const char* kSessionCookie = "idms_session";

}  // namespace idms::server
