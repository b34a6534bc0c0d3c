// The sessions' REST routes: list, one session with its events, the recording (with HTTP range
// requests), delete. Added to the route table by the server (they need the live sessions).
#include <sys/stat.h>

#include <algorithm>
#include <nlohmann/json.hpp>

#include "idms/protocol/recording.h"
#include "idms/server/http_parse.h"
#include "sessions.h"

namespace idms::server {
namespace {

using json = nlohmann::json;

json RowJson(const SessionRow& r, int viewers) {
  json summary = json::object();
  if (!r.summary_json.empty()) summary = json::parse(r.summary_json, nullptr, false);
  return json{{"id", r.id},           {"state", r.state},           {"model", r.model},
              {"device", r.device},   {"identity", r.identity},     {"trainee", r.trainee},
              {"started", r.started}, {"duration_s", r.duration_s}, {"samples", r.samples},
              {"viewers", viewers},   {"summary", summary}};
}

// GET /api/sessions/{id}/recording.mcap: streamed from the file (FileRangeBody), with one byte
// range (RFC 9110 14) on GET. The ETag is the size and modification time (a live recording
// grows), so that If-Range resumes a download only while the bytes are the same.
HandlerResponse GetRecording(SessionHub& hub, ApiRequest& req) {
  const std::optional<SessionRow> r = hub.Get(req.params[0]);
  if (!r) return JsonError(req, http::status::not_found, "no session " + req.params[0]);
  boost::beast::file file;
  boost::beast::error_code ec;
  file.open(hub.RecordingPath(*r).c_str(), boost::beast::file_mode::scan, ec);
  struct stat st {};
  if (ec || ::fstat(file.native_handle(), &st) != 0 || !S_ISREG(st.st_mode))
    return JsonError(req, http::status::not_found, "session " + r->id + " has no recording");
  const uint64_t size = static_cast<uint64_t>(st.st_size);
  const std::string etag =
      "\"" + std::to_string(size) + "-" + std::to_string(st.st_mtim.tv_sec * 1000000000LL + st.st_mtim.tv_nsec) + "\"";
  // Range on GET only (RFC 9110 14.2), and only while If-Range (if any) names this ETag (13.1.5;
  // a date never matches: the recording has no Last-Modified).
  const auto range = req.message.find(http::field::range);
  const auto if_range = req.message.find(http::field::if_range);
  ByteRange wanted{0, size == 0 ? 0 : size - 1};
  RangeRequest kind = RangeRequest::kWhole;
  if (range != req.message.end() && req.message.method() == http::verb::get &&
      (if_range == req.message.end() || Sv(if_range->value()) == etag))
    kind = ParseRange(Sv(range->value()), size, &wanted);
  if (kind == RangeRequest::kUnsatisfiable) {
    ApiResponse res = JsonError(req, http::status::range_not_satisfiable, "range not satisfiable");
    res.set(http::field::content_range, "bytes */" + std::to_string(size));
    return res;
  }
  FileResponse res{http::status::ok, req.message.version()};
  if (kind == RangeRequest::kPartial) {
    res.result(http::status::partial_content);
    res.set(http::field::content_range,
            "bytes " + std::to_string(wanted.first) + "-" + std::to_string(wanted.last) + "/" + std::to_string(size));
  }
  res.set(http::field::content_type, "application/x-mcap");
  res.set(http::field::accept_ranges, "bytes");
  res.set(http::field::etag, etag);
  res.set(http::field::content_disposition, "attachment; filename=\"" + r->id + ".mcap\"");
  res.body().file = std::move(file);
  res.body().offset = kind == RangeRequest::kPartial ? wanted.first : 0;
  res.body().length = kind == RangeRequest::kPartial ? wanted.last - wanted.first + 1 : size;
  return res;
}

}  // namespace

void AppendSessionRoutes(ServerCore& core, std::vector<Route>* routes) {
  using P = Permission;
  using V = http::verb;
  SessionHub* hub = core.hub;
  // ?trainee=NAME&model=NAME (exact), ?from=DATE&to=DATE (UTC, "2026-11-27" or a longer ISO 8601
  // prefix; both ends included): the sessions that match all, newest first.
  routes->push_back({V::get, "/api/sessions", P::kRead, false, false, [hub](ApiContext&, ApiRequest& req) {
                       const auto param = [&req](const char* key) {
                         const auto it = req.query.find(key);
                         return it == req.query.end() ? std::string() : it->second;
                       };
                       const std::string trainee = param("trainee"), model = param("model"), from = param("from"),
                                         to = param("to");
                       json list = json::array();
                       for (const SessionRow& r : hub->List()) {
                         if (req.query.count("trainee") && r.trainee != trainee) continue;
                         if (!model.empty() && r.model != model) continue;
                         if (!from.empty() && r.started.substr(0, from.size()) < from) continue;
                         if (!to.empty() && r.started.substr(0, to.size()) > to) continue;
                         const auto live = hub->FindLive(r.id);
                         list.push_back(RowJson(r, live ? live->viewers() : 0));
                       }
                       return JsonResponse(req, http::status::ok, JsonText(json{{"sessions", list}}));
                     }});
  routes->push_back({V::get, "/api/sessions/{id}", P::kRead, false, false,
                     [hub](ApiContext&, ApiRequest& req) {
                       const std::optional<SessionRow> r = hub->Get(req.params[0]);
                       if (!r) return JsonError(req, http::status::not_found, "no session " + req.params[0]);
                       const auto live = hub->FindLive(r->id);
                       json out = RowJson(*r, live ? live->viewers() : 0);
                       out["scene"] = r->scene_text;
                       // Its events, from the recording (an unfinished one is read by a scan).
                       json events = json::array();
                       RecordingReader reader;
                       RecordingReaderOptions options;
                       options.device = options.mesh = false;
                       json annotations = json::array();
                       std::string error;
                       if (reader.Open(hub->RecordingPath(*r), options, &error)) {
                         RecordedMessage m;
                         while (reader.Next(&m, &error)) {
                           if (m.envelope.has_annotation()) {
                             const v1::Annotation& a = m.envelope.annotation();
                             annotations.push_back(
                                 {{"id", a.id()}, {"time_s", a.time_s()}, {"text", a.text()}, {"author", a.author()}});
                             continue;
                           }
                           if (!m.envelope.has_session_event()) continue;
                           const v1::SessionEvent& e = m.envelope.session_event();
                           events.push_back({{"kind", v1::SessionEvent::Kind_Name(e.kind())},
                                             {"tick", e.tick()},
                                             {"time_s", e.time_s()},
                                             {"count", e.count()},
                                             {"message", e.message()},
                                             {"peer", e.peer()}});
                         }
                       }
                       out["events"] = events;
                       out["annotations"] = annotations;
                       return JsonResponse(req, http::status::ok, JsonText(out));
                     },
                     true});
  routes->push_back({V::get, "/api/sessions/{id}/recording.mcap", P::kRead, false, false,
                     [hub](ApiContext&, ApiRequest& req) { return GetRecording(*hub, req); }, true});
  // {"trainee": "NAME"}: who was at the device, corrected by an admin.
  routes->push_back(
      {V::patch, "/api/sessions/{id}", P::kWrite, false, false,
       [hub](ApiContext&, ApiRequest& req) {
         const json body = json::parse(req.message.body(), nullptr, false);
         if (!body.is_object() || !body.contains("trainee") || !body["trainee"].is_string()) {
           return JsonError(req, http::status::bad_request, "expected a JSON object {\"trainee\": \"NAME\"}");
         }
         const std::string trainee = body["trainee"];
         const bool printable = std::all_of(trainee.begin(), trainee.end(),
                                            [](char c) { return static_cast<unsigned char>(c) >= 0x20 && c != 0x7f; });
         if (trainee.size() > 256 || !printable) {
           return JsonError(req, http::status::bad_request, "trainee: at most 256 bytes, no control characters");
         }
         std::string error;
         if (!hub->SetTrainee(req.params[0], trainee, &error)) {
           return JsonError(req, http::status::not_found, error);
         }
         const std::optional<SessionRow> r = hub->Get(req.params[0]);
         return JsonResponse(req, http::status::ok, JsonText(RowJson(*r, 0)));
       },
       true});
  routes->push_back({V::delete_, "/api/sessions/{id}", P::kWrite, false, false,
                     [hub](ApiContext&, ApiRequest& req) {
                       std::string error;
                       if (!hub->Delete(req.params[0], &error)) {
                         return JsonError(
                             req, hub->FindLive(req.params[0]) ? http::status::conflict : http::status::not_found,
                             error);
                       }
                       return JsonResponse(req, http::status::ok, JsonText(json{{"deleted", req.params[0]}}));
                     },
                     true});
}

}  // namespace idms::server
