// The sessions' REST routes: list, one session with its events, the recording (with HTTP range
// requests), delete. Added to the route table by the server (they need the live sessions).
#include <fstream>
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
  return json{{"id", r.id},
              {"state", r.state},
              {"model", r.model},
              {"device", r.device},
              {"identity", r.identity},
              {"started", r.started},
              {"duration_s", r.duration_s},
              {"samples", r.samples},
              {"viewers", viewers},
              {"summary", summary}};
}

}  // namespace

void AppendSessionRoutes(ServerCore& core, std::vector<Route>* routes) {
  using P = Permission;
  using V = http::verb;
  SessionHub* hub = core.hub;
  routes->push_back({V::get, "/api/sessions", P::kRead, false, false, [hub](ApiContext&, ApiRequest& req) {
                       json list = json::array();
                       for (const SessionRow& r : hub->List()) {
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
                     [hub](ApiContext&, ApiRequest& req) {
                       const std::optional<SessionRow> r = hub->Get(req.params[0]);
                       if (!r) return JsonError(req, http::status::not_found, "no session " + req.params[0]);
                       std::ifstream in(hub->RecordingPath(*r), std::ios::binary | std::ios::ate);
                       if (!in)
                         return JsonError(req, http::status::not_found, "session " + r->id + " has no recording");
                       const uint64_t size = static_cast<uint64_t>(in.tellg());
                       uint64_t first = 0, last = size == 0 ? 0 : size - 1;
                       ApiResponse res{http::status::ok, req.message.version()};
                       // Range on GET only (RFC 9110 14.2: ignored on any other method).
                       const auto range = req.message.find(http::field::range);
                       ByteRange wanted;
                       const RangeRequest kind = range == req.message.end() || req.message.method() != http::verb::get
                                                     ? RangeRequest::kWhole
                                                     : ParseRange(Sv(range->value()), size, &wanted);
                       if (kind == RangeRequest::kUnsatisfiable) {
                         res = JsonError(req, http::status::range_not_satisfiable, "range not satisfiable");
                         res.set(http::field::content_range, "bytes */" + std::to_string(size));
                         return res;
                       }
                       if (kind == RangeRequest::kPartial) {
                         first = wanted.first, last = wanted.last;
                         res.result(http::status::partial_content);
                         res.set(http::field::content_range, "bytes " + std::to_string(first) + "-" +
                                                                 std::to_string(last) + "/" + std::to_string(size));
                       }
                       res.body().resize(size == 0 ? 0 : last - first + 1);
                       in.seekg(static_cast<std::streamoff>(first));
                       in.read(res.body().data(), static_cast<std::streamsize>(res.body().size()));
                       res.set(http::field::content_type, "application/x-mcap");
                       res.set(http::field::accept_ranges, "bytes");
                       res.set(http::field::content_disposition, "attachment; filename=\"" + r->id + ".mcap\"");
                       return res;
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
