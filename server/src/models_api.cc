// The model library's REST handlers: list, metadata with versions, file downloads with ETag and
// immutable caching, uploads (JSON or multipart) validated before anything is stored, deletes.
#include <charconv>
#include <cmath>
#include <nlohmann/json.hpp>

#include "idms/server/api.h"
#include "idms/server/http_parse.h"
#include "idms/server/log.h"

namespace idms::server {
namespace {

using json = nlohmann::json;

}  // namespace

json ModelVersionJson(const ModelVersion& v) {
  return json{{"name", v.name},
              {"version", v.version},
              {"description", v.description},
              {"created", v.created},
              {"atoms", v.atoms},
              {"elements", v.elements},
              {"triangles", v.triangles},
              {"bytes", v.bytes},
              {"fem_sha256", v.fem_sha256},
              {"plg_sha256", v.plg_sha256},
              {"obj_sha256", v.obj_sha256}};
}

void PublishModelAdded(ApiContext& ctx, const ModelVersion& v) {
  if (ctx.publish_library_event) {
    ctx.publish_library_event(JsonText(json{{"event", "model_added"}, {"model", ModelVersionJson(v)}}));
  }
}

namespace {

// ?version=N: 0 when absent, -1 when malformed.
int64_t RequestedVersion(const ApiRequest& req) {
  const auto it = req.query.find("version");
  if (it == req.query.end()) return 0;
  int64_t v = -1;
  const std::string& s = it->second;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return ec == std::errc() && end == s.data() + s.size() && v > 0 ? v : -1;
}

ApiResponse BadVersion(const ApiRequest& req) {
  return JsonError(req, http::status::bad_request, "version must be a positive integer");
}

ApiResponse NotFound(const ApiRequest& req, const std::string& name, int64_t version) {
  return JsonError(req, http::status::not_found,
                   "no model '" + name + "'" + (version > 0 ? " version " + std::to_string(version) : ""));
}

// The upload's three fields from a JSON or multipart body; false with the response to send.
bool ReadUploadFields(const ApiRequest& req, std::string* fem, std::string* plg, std::string* description,
                      ApiResponse* refusal) {
  if (req.message.body().empty()) {
    *refusal = JsonError(req, http::status::bad_request, "the upload has no body");
    return false;
  }
  MediaType type;
  ParseMediaType(Sv(req.message[http::field::content_type]), &type);  // checked at admission
  if (type.type == "application/json") {
    try {
      const json body = json::parse(req.message.body());
      if (!body.is_object() || !body.contains("fem") || !body.contains("plg")) {
        *refusal = JsonError(req, http::status::bad_request,
                             "expected {\"fem\": TEXT, \"plg\": TEXT, "
                             "\"description\": TEXT}");
        return false;
      }
      *fem = body.at("fem").get<std::string>();
      *plg = body.at("plg").get<std::string>();
      *description = body.value("description", std::string());
    } catch (const std::exception& e) {
      *refusal = JsonError(req, http::status::bad_request, std::string("malformed JSON body: ") + e.what());
      return false;
    }
    return true;
  }
  std::vector<FormPart> parts;
  std::string error;
  if (!ParseMultipart(req.message.body(), type.params["boundary"], &parts, &error)) {
    *refusal = JsonError(req, http::status::bad_request, error);
    return false;
  }
  bool have_fem = false, have_plg = false;
  for (const FormPart& p : parts) {
    if (p.name == "fem") *fem = std::string(p.data), have_fem = true;
    if (p.name == "plg") *plg = std::string(p.data), have_plg = true;
    if (p.name == "description") *description = std::string(p.data);
  }
  if (!have_fem || !have_plg) {
    *refusal = JsonError(req, http::status::bad_request, "multipart upload needs parts 'fem' and 'plg'");
    return false;
  }
  return true;
}

}  // namespace

ApiResponse ListModels(ApiContext& ctx, ApiRequest& req) {
  json models = json::array();
  for (const ModelVersion& v : ctx.library->models().ListLatest()) {
    models.push_back({{"name", v.name},
                      {"latest_version", v.version},
                      {"atoms", v.atoms},
                      {"elements", v.elements},
                      {"triangles", v.triangles},
                      {"bytes", v.bytes},
                      {"description", v.description},
                      {"created", v.created},
                      {"thumbnail", "/api/models/" + v.name + "/thumbnail.png?version=" + std::to_string(v.version)}});
  }
  return JsonResponse(req, http::status::ok, JsonText(json{{"models", models}}));
}

ApiResponse GetModel(ApiContext& ctx, ApiRequest& req) {
  const std::string& name = req.params[0];
  const int64_t version = RequestedVersion(req);
  if (version < 0) return BadVersion(req);
  const std::optional<ModelRecord> rec = ctx.library->models().Get(name);
  if (!rec) return NotFound(req, name, 0);
  const ModelVersion* chosen = &rec->latest();
  if (version > 0) {
    chosen = nullptr;
    for (const ModelVersion& v : rec->versions) chosen = v.version == version ? &v : chosen;
    if (chosen == nullptr) return NotFound(req, name, version);
  }
  // The chosen version's fields at the top level (what the agent's FetchModel reads), then all.
  // Its metadata too (a fit's report, for the model page); the list names only the session a
  // version was fitted to.
  json out = ModelVersionJson(*chosen);
  out["latest_version"] = rec->latest().version;
  if (!chosen->metadata.empty()) out["metadata"] = json::parse(chosen->metadata, nullptr, false);
  json versions = json::array();
  for (const ModelVersion& v : rec->versions) {
    versions.push_back(ModelVersionJson(v));
    if (v.metadata.empty()) continue;
    const json m = json::parse(v.metadata, nullptr, false);
    if (m.is_object() && m.contains("fit") && m["fit"].is_object() && m["fit"].contains("session")) {
      versions.back()["fitted_to_session"] = m["fit"]["session"];
    }
  }
  out["versions"] = versions;
  return JsonResponse(req, http::status::ok, JsonText(out));
}

ApiResponse GetModelFile(ApiContext& ctx, ApiRequest& req) {
  const std::string& name = req.params[0];
  const std::string& file = req.params[1];
  if (file != "fem" && file != "plg" && file != "obj")
    return JsonError(req, http::status::not_found, "no file '" + file + "': expected fem, plg or obj");
  const int64_t version = RequestedVersion(req);
  if (version < 0) return BadVersion(req);
  const std::optional<ModelVersion> v = ctx.library->Find(name, version);
  if (!v) return NotFound(req, name, version);
  const std::string& sha = file == "fem" ? v->fem_sha256 : file == "plg" ? v->plg_sha256 : v->obj_sha256;
  const std::string etag = "\"" + sha + "\"";
  // A named version never changes; the latest may.
  const char* cache = version > 0 ? "public, max-age=31536000, immutable" : "no-cache";
  const auto inm = req.message.find(http::field::if_none_match);
  if (inm != req.message.end() && (inm->value() == etag || inm->value() == "*")) {
    ApiResponse res{http::status::not_modified, req.message.version()};
    res.set(http::field::etag, etag);
    res.set(http::field::cache_control, cache);
    return res;
  }
  ApiResponse res{http::status::ok, req.message.version()};
  if (!ctx.library->blobs().Get(sha, &res.body()))
    return JsonError(req, http::status::internal_server_error, "the stored " + file + " of " + name + " is missing");
  res.set(http::field::content_type, file == "obj" ? "model/obj" : "text/plain; charset=utf-8");
  res.set(http::field::etag, etag);
  res.set(http::field::cache_control, cache);
  res.set(http::field::content_disposition, "inline; filename=\"" + name + "." + file + "\"");
  return res;
}

ApiResponse PutModel(ApiContext& ctx, ApiRequest& req) {
  const std::string& name = req.params[0];
  if (!ValidModelName(name))
    return JsonError(req, http::status::bad_request,
                     "model name '" + name + "': expected 1-64 of [A-Za-z0-9_.-], not starting with '.', no '..'");
  std::string fem, plg, description;
  ApiResponse refusal;
  if (!ReadUploadFields(req, &fem, &plg, &description, &refusal)) return refusal;
  UploadError error;
  UploadTimings timings;
  const std::optional<ModelVersion> v = ctx.library->Upload(name, fem, plg, description, &error, &timings);
  if (!v) {
    json body{{"error", error.message}};
    if (!error.file.empty()) body.update({{"file", error.file}, {"line", error.line}, {"column", error.column}});
    return JsonResponse(req, static_cast<http::status>(error.status), JsonText(body));
  }
  Log(LogLevel::kInfo, "model stored",
      {{"name", name},
       {"version", v->version},
       {"atoms", v->atoms},
       {"bytes", v->bytes},
       {"parse_ms", std::round(timings.parse_ms * 10) / 10},
       {"store_ms", std::round(timings.store_ms * 10) / 10}});
  PublishModelAdded(ctx, *v);
  ApiResponse res = JsonResponse(req, http::status::created, JsonText(ModelVersionJson(*v)));
  res.set(http::field::location, "/api/models/" + name + "?version=" + std::to_string(v->version));
  return res;
}

ApiResponse DeleteModel(ApiContext& ctx, ApiRequest& req) {
  const std::string& name = req.params[0];
  const int64_t version = RequestedVersion(req);
  if (version < 0) return BadVersion(req);
  if (!ctx.library->Delete(name, version)) return NotFound(req, name, version);
  if (ctx.publish_library_event)
    ctx.publish_library_event(JsonText(json{{"event", "model_deleted"}, {"name", name}, {"version", version}}));
  return JsonResponse(req, http::status::ok, JsonText(json{{"deleted", name}, {"version", version}}));
}

}  // namespace idms::server
