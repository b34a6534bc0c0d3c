// The sessions' REST routes: list, one session with its events, the recording (with HTTP range
// requests), delete. Added to the route table by the server (they need the live sessions).
#include <fcntl.h>
#include <google/protobuf/text_format.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>

#include "frame_checks.h"
#include "idms/protocol/recording.h"
#include "idms/server/auth.h"
#include "idms/server/http_parse.h"
#include "session_summary.h"
#include "sessions.h"

namespace idms::server {
namespace {

using json = nlohmann::json;

// The session's figures against its scene's limits (Scene.grading): {"passed", "checks": [{"figure",
// "limit", "value", "passed"}]}; null when the scene sets none.
json GradeJson(const v1::Scene& scene, const json& summary) {
  if (!scene.has_grading() || !summary.is_object()) return nullptr;
  const v1::Grading& g = scene.grading();
  json checks = json::array();
  bool passed = true;
  const auto check = [&](const char* figure, bool has, double limit) {
    if (!has) return;
    const double value = summary.value(figure, 0.0);
    const bool ok = value <= limit;
    passed = passed && ok;
    checks.push_back({{"figure", figure}, {"limit", limit}, {"value", value}, {"passed", ok}});
  };
  check("peak_force", g.has_max_peak_force(), g.max_peak_force());
  check("contact_time_s", g.has_max_contact_time_s(), g.max_contact_time_s());
  check("path_length", g.has_max_path_length(), g.max_path_length());
  check("force_limit_hits", g.has_max_force_limit_hits(), g.max_force_limit_hits());
  if (checks.empty()) return nullptr;
  return json{{"passed", passed}, {"checks", checks}};
}

// The scene's units (Scene.units), for the pages to convert and label: {} when it names none.
json UnitsJson(const v1::Scene& scene) {
  json units = json::object();
  if (scene.units().has_mm_per_unit()) units["mm_per_unit"] = scene.units().mm_per_unit();
  if (scene.units().has_newtons_per_force_unit()) {
    units["newtons_per_force_unit"] = scene.units().newtons_per_force_unit();
  }
  return units;
}

json RowJson(const SessionRow& r, int viewers) {
  json summary = json::object();
  if (!r.summary_json.empty()) summary = json::parse(r.summary_json, nullptr, false);
  // Grading and units come from the scene, parsed only when it has either.
  v1::Scene scene;
  if (r.scene_text.find("grading") != std::string::npos || r.scene_text.find("units") != std::string::npos) {
    if (!google::protobuf::TextFormat::ParseFromString(r.scene_text, &scene)) scene.Clear();
  }
  return json{{"id", r.id},
              {"state", r.state},
              {"model", r.model},
              {"device", r.device},
              {"identity", r.identity},
              {"trainee", r.trainee},
              {"started", r.started},
              {"duration_s", r.duration_s},
              {"samples", r.samples},
              {"viewers", viewers},
              {"summary", summary},
              {"grade", GradeJson(scene, summary)},
              {"units", UnitsJson(scene)}};
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

// GET /api/sessions/{id}/samples.csv: every device sample of the recording, one line each. Written
// on a worker into an unnamed file beside the recordings (O_TMPFILE: gone when its descriptor
// closes, even after a crash), then streamed from it: memory stays bounded whatever the length.
HandlerResponse GetSamplesCsv(SessionHub& hub, ApiRequest& req) {
  const std::optional<SessionRow> r = hub.Get(req.params[0]);
  if (!r) return JsonError(req, http::status::not_found, "no session " + req.params[0]);
  const std::string path = hub.RecordingPath(*r);
  RecordingReader reader;
  RecordingReaderOptions options;
  options.mesh = options.events = options.annotations = false;
  std::string error;
  if (!reader.Open(path, options, &error)) {
    return JsonError(req, http::status::not_found, "session " + r->id + " has no readable recording: " + error);
  }
  const std::string dir = path.substr(0, path.find_last_of('/'));
  const int fd = ::open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd < 0) return JsonError(req, http::status::internal_server_error, "no temporary file for the CSV");
  boost::beast::file file;
  file.native_handle(fd);  // owns it from here
  // Friction's columns (as idms-sim run --csv names them) after the first twelve, so that readers
  // of those keep working; zero and "none" without friction.
  std::string text =
      "tick,time_s,x,y,z,fx,fy,fz,contact,force_limited,num_contacts,warnings,ftx,fty,ftz,ft,fn,friction\n";
  bool ok = true;
  const auto flush = [&] {
    boost::beast::error_code ec;
    for (size_t done = 0; ok && done < text.size();) {
      done += file.write(text.data() + done, text.size() - done, ec);
      ok = !ec;
    }
    text.clear();
  };
  RecordedMessage m;
  char line[480];
  static constexpr const char* kFriction[] = {"none", "stick", "slip"};
  while (ok && reader.Next(&m, &error)) {
    if (!m.envelope.has_device_samples()) continue;
    for (const v1::DeviceSample& s : m.envelope.device_samples().samples()) {
      const v1::Vec3& ft = s.friction_force();
      const int state = s.friction() >= 0 && s.friction() <= 2 ? static_cast<int>(s.friction()) : 0;
      const int n = std::snprintf(
          line, sizeof line, "%llu,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%d,%d,%u,%u,%.9g,%.9g,%.9g,%.9g,%.9g,%s\n",
          static_cast<unsigned long long>(s.tick()), s.time_s(), s.tool_pos().x(), s.tool_pos().y(), s.tool_pos().z(),
          s.force().x(), s.force().y(), s.force().z(), s.contact() ? 1 : 0, s.force_limited() ? 1 : 0, s.num_contacts(),
          s.warnings(), ft.x(), ft.y(), ft.z(), std::hypot(ft.x(), ft.y(), ft.z()), s.normal_force(), kFriction[state]);
      text.append(line, static_cast<size_t>(std::max(n, 0)));
    }
    if (text.size() >= (1u << 20)) flush();
  }
  flush();
  boost::beast::error_code ec;
  const uint64_t size = ok ? file.size(ec) : 0;
  if (!ok || ec) return JsonError(req, http::status::internal_server_error, "the CSV could not be written");
  FileResponse res{http::status::ok, req.message.version()};
  res.set(http::field::content_type, "text/csv; charset=utf-8");
  res.set(http::field::content_disposition, "attachment; filename=\"" + r->id + "-samples.csv\"");
  res.body().file = std::move(file);
  res.body().offset = 0;
  res.body().length = size;
  return res;
}

// The device force over the whole session, peak-preserving: ?points=N (10 to 10000, default 1000)
// equal slices of session time, each given by its largest |F| and that sample's time; empty
// slices are left out. What a plot of a whole session, or two overlaid, needs.
HandlerResponse GetForceProfile(SessionHub& hub, ApiRequest& req) {
  const std::optional<SessionRow> r = hub.Get(req.params[0]);
  if (!r) return JsonError(req, http::status::not_found, "no session " + req.params[0]);
  int points = 1000;
  if (const auto it = req.query.find("points"); it != req.query.end()) {
    char* end = nullptr;
    const long n = std::strtol(it->second.c_str(), &end, 10);
    if (it->second.empty() || *end != '\0' || n < 10 || n > 10000) {
      return JsonError(req, http::status::bad_request, "points: a whole number from 10 to 10000");
    }
    points = static_cast<int>(n);
  }
  const SessionSummary summary = SessionSummary::FromJson(r->summary_json);
  const double t0 = std::max(summary.first_time_s, 0.0), span = std::max(summary.last_time_s - t0, 1e-9);
  RecordingReader reader;
  RecordingReaderOptions options;
  options.mesh = options.events = options.annotations = false;
  std::string error;
  if (!reader.Open(hub.RecordingPath(*r), options, &error)) {
    return JsonError(req, http::status::not_found, "session " + r->id + " has no readable recording: " + error);
  }
  std::vector<double> peak(static_cast<size_t>(points), -1), at(static_cast<size_t>(points), 0);
  RecordedMessage m;
  while (reader.Next(&m, &error)) {
    if (!m.envelope.has_device_samples()) continue;
    for (const v1::DeviceSample& s : m.envelope.device_samples().samples()) {
      const double f = std::hypot(s.force().x(), s.force().y(), s.force().z());
      const double x = (s.time_s() - t0) / span * points;
      const size_t i = static_cast<size_t>(std::clamp(x, 0.0, points - 1.0));
      if (f > peak[i]) peak[i] = f, at[i] = s.time_s();
    }
  }
  json times = json::array(), forces = json::array();
  for (size_t i = 0; i < peak.size(); ++i) {
    if (peak[i] < 0) continue;
    times.push_back(at[i]);
    forces.push_back(peak[i]);
  }
  return JsonResponse(req, http::status::ok,
                      JsonText(json{{"id", r->id}, {"points", points}, {"time_s", times}, {"force", forces}}));
}

// A note as the API gives it; "added" only for a note added after the session ended.
json NoteJson(const SessionNote& n) {
  json j{{"id", n.id}, {"time_s", n.time_s}, {"text", n.text}, {"author", n.author}};
  if (!n.created.empty()) j["added"] = n.created;
  return j;
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
                             annotations.push_back(NoteJson({a.id(), a.time_s(), a.text(), a.author(), ""}));
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
                       // And the notes added since it ended, by time with the recorded ones.
                       for (const SessionNote& n : hub->index().Notes(r->id)) {
                         annotations.push_back(NoteJson(n));
                       }
                       std::stable_sort(annotations.begin(), annotations.end(), [](const json& a, const json& b) {
                         return a["time_s"].get<double>() < b["time_s"].get<double>();
                       });
                       out["events"] = events;
                       out["annotations"] = annotations;
                       return JsonResponse(req, http::status::ok, JsonText(out));
                     },
                     true});
  // {"time_s": S, "text": "..."}: a note on the session at session time S (0 on a live session:
  // now); any role that may watch may add one, as on the live view. A live session records and
  // broadcasts it; an ended one keeps it beside its recording. 201 with the stamped note.
  routes->push_back({V::post, "/api/sessions/{id}/notes", P::kRead, false, false,
                     [hub](ApiContext&, ApiRequest& req) {
                       const json body = json::parse(req.message.body(), nullptr, false);
                       if (!body.is_object() || !body.contains("text") || !body["text"].is_string() ||
                           (body.contains("time_s") && !body["time_s"].is_number())) {
                         return JsonError(req, http::status::bad_request,
                                          "expected a JSON object {\"time_s\": SECONDS, \"text\": \"NOTE\"}");
                       }
                       v1::Annotation check;
                       check.set_text(body["text"].get<std::string>());
                       check.set_time_s(body.value("time_s", 0.0));
                       std::string error;
                       if (!CheckAnnotation(check, &error)) return JsonError(req, http::status::bad_request, error);
                       bool not_found = false;
                       const std::optional<SessionNote> note =
                           hub->AddNote(req.params[0], check.time_s(), check.text(),
                                        std::string(RoleName(req.role)) + " " + req.peer, &error, &not_found);
                       if (!note)
                         return JsonError(req, not_found ? http::status::not_found : http::status::conflict, error);
                       return JsonResponse(req, http::status::created, JsonText(NoteJson(*note)));
                     },
                     true});
  routes->push_back({V::get, "/api/sessions/{id}/recording.mcap", P::kRead, false, false,
                     [hub](ApiContext&, ApiRequest& req) { return GetRecording(*hub, req); }, true});
  routes->push_back({V::get, "/api/sessions/{id}/force", P::kRead, false, false,
                     [hub](ApiContext&, ApiRequest& req) { return GetForceProfile(*hub, req); }, true});
  routes->push_back({V::get, "/api/sessions/{id}/samples.csv", P::kRead, false, false,
                     [hub](ApiContext&, ApiRequest& req) { return GetSamplesCsv(*hub, req); }, true});
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
