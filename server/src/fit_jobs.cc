// The server's fit jobs (fit_jobs.h): a bounded queue, one thread, a bounded table of jobs by
// session, and the two routes.
#include "fit_jobs.h"

#include <google/protobuf/text_format.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "fit.h"
#include "fit_json.h"
#include "fit_recording.h"
#include "idms/protocol/scene.h"
#include "idms/server/log.h"
#include "idms/sim/model_io.h"
#include "sessions.h"

namespace idms::server {

using json = nlohmann::json;

namespace {

constexpr size_t kMaxQueued = 4;           // waiting behind the running one; more: 503
constexpr size_t kMaxJobsKept = 64;        // finished jobs answered by GET; the oldest go first
constexpr size_t kCurvePoints = 500;       // the report's force curve, measured against fitted
constexpr size_t kMaxRegions = 8;          // in a request
constexpr size_t kMaxRequestBytes = 4096;  // the request's JSON
// A session longer than this is refused: the trace is held whole (48 bytes a tick) and every
// replay steps it all (an hour of the 40 x 40 slab would hold the fit thread for hours).
constexpr double kMaxSessionS = 600;
// The residuals compared at most (every stride-th tick beyond): the solver's Jacobian is
// 3 x this x the parameters, in doubles.
constexpr size_t kMaxComparedSamples = 60000;

// What was asked for, checked.
struct FitRequest {
  std::string session;
  std::string model;    // empty: the session's
  int64_t version = 0;  // 0: the one the session ran
  std::vector<fit::Param> params = {fit::Param::kHomeK, fit::Param::kSurfaceK};
  std::vector<fit::Region> regions;
  std::vector<std::string> region_specs;
  bool map = false;  // a scan's stiffness map (FitMap) instead of a fit of `params`
  std::string by;    // who asked (the token's role)
};

struct Job {
  uint64_t seq = 0;  // order of arrival (the oldest finished one is dropped first)
  FitRequest request;
  std::string state = "queued";  // queued, running, done, failed, stopped
  std::string created;           // UTC
  fit::FitProgress progress;
  std::string error;
  json result;  // done: the new version and the report
};

// Rounded to 4 significant digits: a plot's worth, a quarter of the JSON.
double Round4(double x) {
  if (!(std::abs(x) > 0) || !std::isfinite(x)) return std::isfinite(x) ? 0 : x;
  const double p = std::pow(10.0, 3 - std::floor(std::log10(std::abs(x))));
  return std::round(x * p) / p;
}

// The request's body: {} or {"model": NAME, "version": N, "params": "home_k,surface_k" (or a list),
// "regions": ["lump=sphere:2,1.5,0,0.9", ...]} or {"model", "version", "map": true}. False with
// *error naming the field.
bool ParseFitRequest(const std::string& body, FitRequest* r, std::string* error) {
  if (body.size() > kMaxRequestBytes) return *error = "a fit request is at most 4096 bytes", false;
  if (body.empty()) return true;
  const json j = json::parse(body, nullptr, false);
  if (!j.is_object()) return *error = "expected a JSON object (or no body)", false;
  for (const auto& [key, value] : j.items()) {
    if (key == "model") {
      if (!value.is_string() || !ValidModelName(value.get<std::string>())) {
        return *error = "model: a library model's name", false;
      }
      r->model = value;
    } else if (key == "version") {
      if (!value.is_number_integer() || value.get<int64_t>() < 1) return *error = "version: an integer >= 1", false;
      r->version = value;
    } else if (key == "params") {
      std::string list;
      if (value.is_string()) {
        list = value;
      } else if (value.is_array()) {
        for (const json& p : value) {
          if (!p.is_string()) return *error = "params: names such as \"home_k\"", false;
          list += (list.empty() ? "" : ",") + p.get<std::string>();
        }
      } else {
        return *error = "params: \"home_k,surface_k\" or [\"home_k\", \"surface_k\"]", false;
      }
      if (!fit::ParseParams(list, &r->params, error)) return *error = "params: " + *error, false;
    } else if (key == "regions") {
      if (!value.is_array() || value.size() > kMaxRegions) {
        return *error = "regions: a list of at most 8 \"[NAME=]sphere:cx,cy,cz,r\" or \"[NAME=]box:...\"", false;
      }
      for (const json& s : value) {
        fit::Region region;
        if (!s.is_string() ||
            !fit::ParseRegion(s.get<std::string>(), static_cast<int>(r->regions.size()), &region, error)) {
          return *error = "regions: " + (s.is_string() ? *error : std::string("each a string")), false;
        }
        r->regions.push_back(region);
        r->region_specs.push_back(s);
      }
    } else if (key == "map") {
      if (!value.is_boolean()) return *error = "map: true or false", false;
      r->map = value;
    } else {
      return *error = "unknown field '" + key + "' (model, version, params, regions, map)", false;
    }
  }
  if (r->map && (j.contains("params") || j.contains("regions"))) {
    return *error = "map: a map fits every element's k press by press; give no params or regions with it", false;
  }
  return true;
}

json ProgressJson(const fit::FitProgress& p) {
  json j{{"iteration", p.iteration}, {"replays", p.replays}, {"rms", Round4(p.rms)}};
  if (p.presses_total > 0) j.update({{"presses_done", p.presses_done}, {"presses_total", p.presses_total}});
  return j;
}

}  // namespace

class FitJobs {
 public:
  explicit FitJobs(ServerCore& core) : core_(core), thread_([this] { Loop(); }) {}
  ~FitJobs() {
    Stop();
    Join();
  }

  // 202 with the job; 404, 409 or 503 with the reason.
  ApiResponse Start(ApiRequest& req) {
    FitRequest r;
    std::string error;
    if (!ParseFitRequest(req.message.body(), &r, &error)) return JsonError(req, http::status::bad_request, error);
    r.session = req.params[0];
    r.by = RoleName(req.role);
    const std::optional<SessionRow> row = core_.hub->Get(r.session);
    if (!row) return JsonError(req, http::status::not_found, "no session " + r.session);
    if (row->state == "live") {
      return JsonError(req, http::status::conflict,
                       "session " + r.session + " is live: fit it once it has ended (its recording is whole then)");
    }
    std::lock_guard lock(mu_);
    if (stopping_) return JsonError(req, http::status::service_unavailable, "the server is stopping");
    auto it = jobs_.find(r.session);
    if (it != jobs_.end() && (it->second.state == "queued" || it->second.state == "running")) {
      return JsonError(req, http::status::conflict, "session " + r.session + " is being fitted already");
    }
    if (queue_.size() >= kMaxQueued) {
      ApiResponse res = JsonError(req, http::status::service_unavailable,
                                  "4 fits are waiting already; ask again once one has finished");
      res.set(http::field::retry_after, "10");
      return res;
    }
    Job job;
    job.seq = ++seq_;
    job.request = std::move(r);
    job.created = UtcNow();
    const std::string id = job.request.session;
    jobs_[id] = std::move(job);
    queue_.push_back(id);
    Trim();
    wake_.notify_one();
    ApiResponse res = JsonResponse(req, http::status::accepted, JsonText(JobJson(jobs_[id])));
    res.set(http::field::location, "/api/sessions/" + id + "/fit");
    return res;
  }

  ApiResponse Status(ApiRequest& req) {
    std::lock_guard lock(mu_);
    auto it = jobs_.find(req.params[0]);
    if (it == jobs_.end()) return JsonError(req, http::status::not_found, "no fit of session " + req.params[0]);
    return JsonResponse(req, http::status::ok, JsonText(JobJson(it->second)));
  }

  // Prometheus lines: the jobs waiting and running, and the fits finished by how they ended.
  std::string MetricsText() {
    std::lock_guard lock(mu_);
    std::string out =
        "# HELP idms_fit_jobs Fits waiting and running (POST /api/sessions/{id}/fit).\n"
        "# TYPE idms_fit_jobs gauge\n";
    out += "idms_fit_jobs{state=\"queued\"} " + std::to_string(queue_.size()) + "\n";
    out += "idms_fit_jobs{state=\"running\"} " + std::to_string(running_ ? 1 : 0) + "\n";
    out += "# HELP idms_fits_total Fits finished, by how they ended.\n# TYPE idms_fits_total counter\n";
    for (const char* state : {"done", "failed", "stopped"}) {
      const auto it = finished_.find(state);
      out += std::string("idms_fits_total{result=\"") + state + "\"} " +
             std::to_string(it == finished_.end() ? 0 : it->second) + "\n";
    }
    return out;
  }

  void Stop() {
    std::lock_guard lock(mu_);
    stopping_ = true;
    stop_flag_ = true;
    wake_.notify_all();
  }
  void Join() {
    if (thread_.joinable()) thread_.join();
  }

 private:
  // Under mu_.
  json JobJson(const Job& j) const {
    json out{{"session", j.request.session}, {"state", j.state}, {"created", j.created}, {"by", j.request.by}};
    if (j.state == "queued") {
      size_t ahead = 0;
      for (const std::string& id : queue_) {
        if (id == j.request.session) break;
        ++ahead;
      }
      out["ahead"] = ahead + (running_ ? 1 : 0);
    }
    if (j.state == "running") out["progress"] = ProgressJson(j.progress);
    if (!j.error.empty()) out["error"] = j.error;
    if (!j.result.is_null()) out["result"] = j.result;
    return out;
  }

  // Drops the oldest finished jobs beyond kMaxJobsKept. Under mu_.
  void Trim() {
    while (jobs_.size() > kMaxJobsKept) {
      auto oldest = jobs_.end();
      for (auto it = jobs_.begin(); it != jobs_.end(); ++it) {
        const bool finished = it->second.state != "queued" && it->second.state != "running";
        if (finished && (oldest == jobs_.end() || it->second.seq < oldest->second.seq)) oldest = it;
      }
      if (oldest == jobs_.end()) return;
      jobs_.erase(oldest);
    }
  }

  void Loop() {
    // A lower priority for this thread alone (Linux: a thread's nice value is its own): sessions and
    // requests first. Not 19 by default: beside busy neighbours a nice-19 thread gets ~1% of a core,
    // and a fit of minutes would take hours.
    setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), core_.options.fit_nice);
    for (;;) {
      FitRequest request;
      {
        std::unique_lock lock(mu_);
        wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
        if (stopping_) {
          for (const std::string& id : queue_) jobs_[id].state = "stopped", jobs_[id].error = "the server stopped";
          queue_.clear();
          return;
        }
        Job& job = jobs_[queue_.front()];
        queue_.pop_front();
        job.state = "running";
        running_ = true;
        request = job.request;
      }
      std::string error;
      json result;
      const bool ok = Run(request, &result, &error);
      std::lock_guard lock(mu_);
      running_ = false;
      Job& job = jobs_[request.session];
      if (ok) {
        job.state = "done";
        job.result = std::move(result);
      } else {
        job.state = stopping_ && error == "stopped" ? "stopped" : "failed";
        job.error = error == "stopped" ? "the server stopped" : error;
      }
      ++finished_[job.state];
      Log(ok ? LogLevel::kInfo : LogLevel::kWarn, ok ? "fit done" : "fit failed",
          {{"session", request.session}, {"error", job.error}});
      Trim();
    }
  }

  // False once the server is stopping (the fit then ends at this iteration).
  bool SetProgress(const std::string& id, const fit::FitProgress& p) {
    std::lock_guard lock(mu_);
    jobs_[id].progress = p;
    return !stopping_;
  }

  // The fit itself, on the job's thread: the model, the recording, the solve, the new version.
  bool Run(const FitRequest& r, json* result, std::string* error) {
    try {
      return RunUnguarded(r, result, error);
    } catch (const StoreUnavailable& e) {
      return *error = e.what(), false;
    }
  }

  bool RunUnguarded(const FitRequest& r, json* result, std::string* error) {
    const std::optional<SessionRow> row = core_.hub->Get(r.session);
    if (!row) return *error = "session " + r.session + " was deleted", false;
    // The model: the one named, else the session's (at the version it ran: the one named in its
    // scene, else the latest when the session started).
    v1::Scene scene;
    if (!google::protobuf::TextFormat::ParseFromString(row->scene_text, &scene)) scene.Clear();
    std::string name = r.model;
    int64_t version = r.version;
    if (name.empty()) {
      if (scene.model().empty()) {
        return *error = "session " + r.session + " ran a model file its agent read (" + row->model +
                        "), not a library model: name the model to fit ({\"model\": NAME})",
               false;
      }
      name = scene.model();
      if (const size_t at = name.find('@'); at != std::string::npos) {
        version = std::atoll(name.c_str() + at + 1);
        name.resize(at);
      }
    }
    const std::optional<ModelRecord> rec = core_.ctx.library->models().Get(name);
    if (!rec) return *error = "no model '" + name + "' in the library", false;
    const ModelVersion* from = nullptr;
    const uint64_t started = ParseUtcNs(row->started);
    for (const ModelVersion& v : rec->versions) {
      if (version > 0 ? v.version == version : (from == nullptr || ParseUtcNs(v.created) <= started)) from = &v;
    }
    if (from == nullptr) return *error = "no model '" + name + "' version " + std::to_string(version), false;
    std::string fem, plg;
    if (!core_.ctx.library->blobs().Get(from->fem_sha256, &fem) ||
        !core_.ctx.library->blobs().Get(from->plg_sha256, &plg)) {
      return *error = "model " + name + " v" + std::to_string(from->version) + ": its files are missing", false;
    }
    Model model;
    LoadError le;
    if (!ParseModelText(fem, plg, name, &model, &le)) return *error = le.ToString(), false;
    FinalizeModel(model);

    // The recording, as the trace and the step and tool it was made with.
    if (row->duration_s > kMaxSessionS) {
      char text[160];
      std::snprintf(text, sizeof text, "session %s lasts %.0f s; the fitter takes sessions of at most %.0f s",
                    r.session.c_str(), row->duration_s, kMaxSessionS);
      return *error = text, false;
    }
    if (!core_.hub->recordings().Fetch(r.session, error)) return false;
    const std::string path = core_.hub->RecordingPath(*row);
    fit::Trace trace;
    fit::FitOptions options;
    if (!tool::ReadRecordingTrace(path, model, &trace, &options.step, &options.tool, error)) {
      // Its file name is the server's business: the session's recording, in the client's words.
      if (error->rfind(path, 0) == 0) *error = "session " + r.session + "'s recording" + error->substr(path.size());
      return false;
    }
    options.params = r.params;
    options.regions = r.regions;
    options.stride = static_cast<int>((trace.force.size() + kMaxComparedSamples - 1) / kMaxComparedSamples);
    options.stride = std::max(options.stride, 1);
    options.progress = [this, &r](const fit::FitProgress& p) { return SetProgress(r.session, p); };
    options.stop = &stop_flag_;
    if (r.map) return RunMap(r, name, *from, model, trace, options, result, error);
    const fit::FitResult f = fit::Fit(model, trace, options);
    if (!f.ok) return *error = f.message, false;

    // The report, then the fitted model as the next version with it.
    json params = json::array();
    std::string summary;
    for (size_t i = 0; i < f.names.size(); ++i) {
      params.push_back({{"name", f.names[i]},
                        {"scale", f.scale[i]},
                        {"scale_sigma", f.scale_sigma[i]},
                        {"value", f.value[i]},
                        {"value_sigma", f.value_sigma[i]}});
      char part[96];
      std::snprintf(part, sizeof part, "%s%s x%.4g +- %.2g", summary.empty() ? "" : ", ", f.names[i].c_str(),
                    f.scale[i], f.scale_sigma[i]);
      summary += part;
    }
    json t = json::array(), measured = json::array(), fitted = json::array();
    const size_t n = f.fitted_force.size();
    const size_t step = std::max<size_t>(1, (n + kCurvePoints - 1) / kCurvePoints);
    const int stride = options.stride;
    for (size_t i = 0; i < n; i += step) {
      const size_t tick = (i + 1) * static_cast<size_t>(stride) - 1;  // the compared sample's row
      t.push_back(Round4(static_cast<double>(tick + 1) * trace.dt_s));
      measured.push_back(Round4(trace.force[tick][2]));
      fitted.push_back(Round4(f.fitted_force[i][2]));
    }
    const json report{{"fit",
                       {{"kind", "params"},
                        {"session", r.session},
                        {"from", {{"name", name}, {"version", from->version}}},
                        {"regions", r.region_specs},
                        {"params", params},
                        {"rms_before", f.rms_before},
                        {"rms_after", f.rms_after},
                        {"peak_force", f.peak_force},
                        {"samples", f.samples},
                        {"stride", options.stride},
                        {"iterations", f.iterations},
                        {"replays", f.replays},
                        {"seconds", Round4(f.seconds)},
                        {"by", r.by},
                        {"curve", {{"component", "fz"}, {"t", t}, {"measured", measured}, {"fitted", fitted}}}}}};
    const std::string description =
        "fitted to session " + r.session + " (from v" + std::to_string(from->version) + "): " + summary;
    const std::optional<ModelVersion> v = StoreVersion(name, f.fitted, description, report, error);
    if (!v) return false;
    *result = {{"model", {{"name", v->name}, {"version", v->version}}},
               {"kind", "params"},
               {"params", params},
               {"rms_before", f.rms_before},
               {"rms_after", f.rms_after},
               {"replays", f.replays},
               {"seconds", Round4(f.seconds)}};
    return true;
  }

  // `fitted` as `name`'s next version with `report` as its metadata, announced on /ws/library.
  std::optional<ModelVersion> StoreVersion(const std::string& name, const Model& fitted, const std::string& description,
                                           const json& report, std::string* error) {
    UploadError upload_error;
    std::optional<ModelVersion> v =
        core_.ctx.library->Upload(name, WriteFem(fitted), WritePlg(fitted), description.substr(0, 1024), &upload_error,
                                  nullptr, JsonText(report));
    if (!v) {
      *error = "storing the fitted model: " + upload_error.message;
      return std::nullopt;
    }
    PublishModelAdded(core_.ctx, *v);
    return v;
  }

  // The scan's stiffness map: the next version is the model with every element's k times the map's
  // background (what the scan says healthy tissue is), the map and the lump in its metadata.
  bool RunMap(const FitRequest& r, const std::string& name, const ModelVersion& from, const Model& model,
              const fit::Trace& trace, const fit::FitOptions& options, json* result, std::string* error) {
    const fit::MapResult m = fit::FitMap(model, trace, options);
    if (!m.ok) return *error = m.message, false;
    Model fitted = model;
    fit::ScaleGroup(fitted, fit::Param::kK, m.background);
    json map = fit::MapJson(m);
    for (json& p : map["points"]) {
      for (auto& [key, value] : p.items()) value = Round4(value.get<double>());  // a plot's worth
    }
    const json report{{"fit",
                       {{"kind", "map"},
                        {"session", r.session},
                        {"from", {{"name", name}, {"version", from.version}}},
                        {"map", map},
                        {"by", r.by}}}};
    char summary[240];
    if (m.lump.found) {
      std::snprintf(summary, sizeof summary,
                    "%zu presses, k x %.4g; a lump at x %.4g, y %.4g, radius %.3g, %.3g times as stiff",
                    m.points.size(), m.background, m.lump.x, m.lump.y, m.lump.radius, m.lump.ratio);
    } else {
      std::snprintf(summary, sizeof summary, "%zu presses, k x %.4g; no lump", m.points.size(), m.background);
    }
    const std::string description =
        "stiffness map of session " + r.session + " (from v" + std::to_string(from.version) + "): " + summary;
    const std::optional<ModelVersion> v = StoreVersion(name, fitted, description, report, error);
    if (!v) return false;
    *result = {{"model", {{"name", v->name}, {"version", v->version}}},
               {"kind", "map"},
               {"presses", m.points.size()},
               {"background", m.background},
               {"lump", map["lump"]},
               {"replays", m.replays},
               {"seconds", Round4(m.seconds)}};
    return true;
  }

  ServerCore& core_;
  std::mutex mu_;
  std::condition_variable wake_;
  std::deque<std::string> queue_;    // session ids, oldest first
  std::map<std::string, Job> jobs_;  // by session: the latest fit of each
  uint64_t seq_ = 0;
  std::map<std::string, uint64_t> finished_;  // by final state
  bool running_ = false;
  bool stopping_ = false;
  std::atomic<bool> stop_flag_{false};  // stopping_ for the fit's replays, read without the lock
  std::thread thread_;                  // last: starts once the rest is built
};

std::shared_ptr<FitJobs> AppendFitRoutes(ServerCore& core, std::vector<Route>* routes) {
  auto jobs = std::make_shared<FitJobs>(core);
  using V = http::verb;
  using P = Permission;
  routes->push_back({V::post, "/api/sessions/{id}/fit", P::kWrite, false, false,
                     [jobs](ApiContext&, ApiRequest& req) { return jobs->Start(req); }, true});
  routes->push_back({V::get, "/api/sessions/{id}/fit", P::kRead, false, false,
                     [jobs](ApiContext&, ApiRequest& req) { return jobs->Status(req); }});
  return jobs;
}

void StopFits(FitJobs& jobs) { jobs.Stop(); }
std::string FitMetrics(FitJobs& jobs) { return jobs.MetricsText(); }
void JoinFits(FitJobs& jobs) { jobs.Join(); }

}  // namespace idms::server
