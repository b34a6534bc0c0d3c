// Screenshots of sessions and thumbnails of models, rendered on demand by one render thread that
// owns the OSMesa context (made once). A request first looks in a content-addressed cache (the
// recording's identity or the model's hashes, plus the parameters; LRU, bounded in bytes), then
// takes one of kMaxRenders slots (beyond them: 503 + Retry-After, so a burst never queues without
// bound), reads its frame on the handler's worker thread, has the render thread draw it, and
// encodes the PNG back on the worker, so that the render thread only ever draws.
#include "render_api.h"

#include <sys/stat.h>

#include <charconv>
#include <condition_variable>
#include <deque>
#include <future>
#include <list>
#include <mutex>
#include <thread>
#include <unordered_map>

#include "idms/render/png.h"
#include "idms/render/render.h"
#include "idms/render/source.h"
#include "sessions.h"

namespace idms::server {
namespace {

using render::Image;
using render::RenderOptions;
using render::ViewerState;
using Clock = std::chrono::steady_clock;

constexpr int kMaxRenders = 3;                               // one drawing, two reading or waiting
constexpr size_t kCacheBytes = size_t{64} << 20;             // PNGs kept
constexpr size_t kKeepImageBytes = size_t{1920} * 1080 * 4;  // image buffers kept between requests
constexpr const char* kScreenshotSize = "1280x720";          // defaults
constexpr const char* kThumbnailSize = "320x240";

double Ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

// The render thread, its bounded admission and the PNG cache. Thread-safe.
class RenderService {
 public:
  RenderService() : thread_([this] { Run(); }) {}
  ~RenderService() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

  // A cached PNG, or null.
  std::shared_ptr<const std::string> Cached(const std::string& key) {
    std::lock_guard lock(mu_);
    const auto it = cache_.find(key);
    if (it == cache_.end()) return nullptr;
    ++hits_;
    lru_.splice(lru_.begin(), lru_, it->second.lru);
    return it->second.png;
  }

  // Prometheus lines for /metrics.
  std::string MetricsText() {
    std::lock_guard lock(mu_);
    auto counter = [](const char* name, const char* help, const std::string& v) {
      return std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " counter\n" + name + " " + v + "\n";
    };
    return counter("idms_render_images_total", "Screenshots and thumbnails rendered.", std::to_string(renders_)) +
           counter("idms_render_cache_hits_total", "Screenshots and thumbnails served from the cache.",
                   std::to_string(hits_)) +
           counter("idms_render_busy_total", "Render requests refused with 503 (every slot taken).",
                   std::to_string(busy_)) +
           counter("idms_render_seconds_total", "Time spent drawing (the render thread), s.",
                   std::to_string(render_s_)) +
           "# HELP idms_render_cache_bytes PNG bytes in the render cache.\n# TYPE idms_render_cache_bytes gauge\n"
           "idms_render_cache_bytes " +
           std::to_string(cache_bytes_) + "\n";
  }

  void Store(const std::string& key, std::shared_ptr<const std::string> png) {
    std::lock_guard lock(mu_);
    if (png->size() > kCacheBytes / 4 || cache_.count(key) != 0) return;
    lru_.push_front(key);
    cache_bytes_ += png->size();
    cache_.emplace(key, Entry{std::move(png), lru_.begin()});
    while (cache_bytes_ > kCacheBytes) {
      const auto victim = cache_.find(lru_.back());
      cache_bytes_ -= victim->second.png->size();
      cache_.erase(victim);
      lru_.pop_back();
    }
  }

  // A render slot, held for the whole request, with an image to draw into (reused: a fresh
  // 1280x720 buffer costs a millisecond of page faults); null when every slot is taken.
  std::unique_ptr<Image> TryReserve() {
    std::lock_guard lock(mu_);
    if (reserved_ >= kMaxRenders) return ++busy_, nullptr;
    ++reserved_;
    if (images_.empty()) return std::make_unique<Image>();
    std::unique_ptr<Image> image = std::move(images_.back());
    images_.pop_back();
    return image;
  }
  void Release(std::unique_ptr<Image> image) {
    std::lock_guard lock(mu_);
    --reserved_;
    // Kept for the next request unless it is larger than a 1080p image (a 4K one is 33 MB).
    if (image->rgba.capacity() > kKeepImageBytes) image->rgba = {};
    images_.push_back(std::move(image));
  }

  // Draws on the render thread; blocks the caller (a worker holding a slot) until it is done.
  bool Draw(const ViewerState& state, const RenderOptions& options, Image* image, std::string* error) {
    std::packaged_task<bool()> task([&] {
      const auto t0 = Clock::now();
      const bool ok = renderer_->Render(state.View(), options, image, error);
      std::lock_guard lock(mu_);
      ++renders_;
      render_s_ += std::chrono::duration<double>(Clock::now() - t0).count();
      return ok;
    });
    std::future<bool> done = task.get_future();
    {
      std::lock_guard lock(mu_);
      queue_.push_back(std::move(task));
    }
    cv_.notify_one();
    return done.get();
  }

 private:
  void Run() {
    renderer_ = std::make_unique<render::Renderer>();  // the context belongs to this thread
    while (true) {
      std::packaged_task<bool()> task;
      {
        std::unique_lock lock(mu_);
        cv_.wait(lock, [&] { return stop_ || !queue_.empty(); });
        if (queue_.empty()) break;
        task = std::move(queue_.front());
        queue_.pop_front();
      }
      task();
    }
    renderer_.reset();  // the context ends on the thread that made it
  }

  struct Entry {
    std::shared_ptr<const std::string> png;
    std::list<std::string>::iterator lru;
  };
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::packaged_task<bool()>> queue_;  // at most kMaxRenders
  bool stop_ = false;
  int reserved_ = 0;
  std::vector<std::unique_ptr<Image>> images_;  // at most kMaxRenders
  uint64_t renders_ = 0, hits_ = 0, busy_ = 0;
  double render_s_ = 0;
  std::unordered_map<std::string, Entry> cache_;
  std::list<std::string> lru_;  // most recent first
  size_t cache_bytes_ = 0;
  std::unique_ptr<render::Renderer> renderer_;
  std::thread thread_;  // last: starts after the members above exist
};

// Releases a render slot (and its image) at the end of the request.
struct Slot {
  RenderService* service;
  std::unique_ptr<Image> image;
  ~Slot() { service->Release(std::move(image)); }
};

// The query of a render: size, wireframe, tool, force and t; anything else is refused.
struct RenderQuery {
  RenderOptions options;
  double t_s = -1;  // -1: absent
};

bool Flag(const std::string& value, bool* out) {
  if (value != "0" && value != "1") return false;
  *out = value == "1";
  return true;
}

bool ParseQuery(const ApiRequest& req, bool with_time, const char* default_size, RenderQuery* q, std::string* error) {
  q->options.show_tool = q->options.show_force = with_time;
  render::ParseSize(default_size, &q->options.width, &q->options.height, error);
  for (const auto& [key, value] : req.query) {
    bool ok = true;
    if (key == "size") {
      ok = render::ParseSize(value, &q->options.width, &q->options.height, error);
    } else if (key == "t" && with_time) {
      ok = render::ParseSeconds(value, &q->t_s, error);
      if (!ok) *error = "t: " + *error;
    } else if (key == "wireframe" || key == "tool" || key == "force") {
      bool* flag = key == "wireframe" ? &q->options.wireframe
                   : key == "tool"    ? &q->options.show_tool
                                      : &q->options.show_force;
      ok = Flag(value, flag);
      if (!ok) *error = key + ": expected 0 or 1, got '" + value.substr(0, 32) + "'";
    } else if (key != "version" || with_time) {
      *error = "unknown parameter '" + key.substr(0, 32) + "': expected " +
               (with_time ? "t, size, wireframe, tool, force" : "version, size, wireframe");
      ok = false;
    }
    if (!ok) return false;
  }
  return true;
}

std::string OptionsKey(const RenderOptions& o) {
  return std::to_string(o.width) + "x" + std::to_string(o.height) + (o.wireframe ? "w" : "s") +
         (o.show_tool ? "t" : "-") + (o.show_force ? "f" : "-");
}

ApiResponse Png(const ApiRequest& req, const std::shared_ptr<const std::string>& png, const std::string& etag,
                const char* cache_control, const std::string& how) {
  ApiResponse res{http::status::ok, req.message.version()};
  res.set(http::field::content_type, "image/png");
  res.set(http::field::etag, etag);
  res.set(http::field::cache_control, cache_control);
  res.set("Server-Timing", how);
  res.body() = *png;
  return res;
}

// 304 when the client holds this ETag.
std::optional<ApiResponse> NotModified(const ApiRequest& req, const std::string& etag, const char* cache_control) {
  const auto inm = req.message.find(http::field::if_none_match);
  if (inm == req.message.end() || inm->value() != etag) return std::nullopt;
  ApiResponse res{http::status::not_modified, req.message.version()};
  res.set(http::field::etag, etag);
  res.set(http::field::cache_control, cache_control);
  return res;
}

ApiResponse Busy(const ApiRequest& req) {
  ApiResponse res = JsonError(req, http::status::service_unavailable,
                              "the renderer is busy (" + std::to_string(kMaxRenders) + " renders in progress); retry");
  res.set(http::field::retry_after, "1");
  return res;
}

// Draws the state on the render thread, encodes it here, caches it.
std::optional<ApiResponse> RenderAndStore(RenderService& service, const ApiRequest& req, const ViewerState& state,
                                          const RenderOptions& options, const std::string& key, Image& image,
                                          std::shared_ptr<const std::string>* png, std::string* timing) {
  std::string error;
  const auto t0 = Clock::now();
  if (!service.Draw(state, options, &image, &error))
    return JsonError(req, http::status::internal_server_error, "render: " + error);
  const auto t1 = Clock::now();
  auto bytes = std::make_shared<std::string>();
  if (!render::EncodePng(image, bytes.get(), &error))
    return JsonError(req, http::status::internal_server_error, "png: " + error);
  const auto t2 = Clock::now();
  *png = bytes;
  service.Store(key, *png);
  char text[96];
  std::snprintf(text, sizeof text, "cache;desc=miss, render;dur=%.2f, png;dur=%.2f", Ms(t0, t1), Ms(t1, t2));
  *timing = text;
  return std::nullopt;
}

ApiResponse Screenshot(RenderService& service, SessionHub& hub, ApiRequest& req) {
  const auto t_start = Clock::now();
  constexpr const char* kCacheControl = "private, no-cache";
  const std::optional<SessionRow> row = hub.Get(req.params[0]);
  if (!row) return JsonError(req, http::status::not_found, "no session " + req.params[0]);
  RenderQuery q;
  std::string error;
  if (!ParseQuery(req, true, kScreenshotSize, &q, &error)) return JsonError(req, http::status::bad_request, error);
  // The recording's identity: a finished file never changes; a live one grows.
  const std::string path = hub.RecordingPath(*row);
  struct stat st {};
  if (row->recording.empty() || ::stat(path.c_str(), &st) != 0)
    return JsonError(req, http::status::not_found, "session " + row->id + " has no recording");
  const std::string key = "session|" + row->id + "|" + std::to_string(st.st_size) + "|" +
                          std::to_string(st.st_mtim.tv_sec) + "." + std::to_string(st.st_mtim.tv_nsec) + "|" +
                          (q.t_s < 0 ? std::string("end") : std::to_string(std::llround(q.t_s * 1e6))) + "|" +
                          OptionsKey(q.options);
  const std::string etag = "\"" + Sha256Hex(key).substr(0, 32) + "\"";
  if (auto res = NotModified(req, etag, kCacheControl)) return *res;
  if (auto png = service.Cached(key)) return Png(req, png, etag, kCacheControl, "cache;desc=hit");
  std::unique_ptr<Image> image = service.TryReserve();
  if (!image) return Busy(req);
  Slot slot{&service, std::move(image)};
  // The surface at t, as a viewer of the replay holds it.
  const auto t_load = Clock::now();
  render::RecordingPlayer player;
  if (!player.Open(path, &error)) return JsonError(req, http::status::internal_server_error, error);
  const double t = q.t_s < 0 ? player.duration_s() : q.t_s;
  if (t > player.duration_s() + 1e-9) {
    char text[128];
    std::snprintf(text, sizeof text, "t=%g s is outside the recording (0 to %.3f s)", t, player.duration_s());
    return JsonError(req, http::status::bad_request, text);
  }
  if (!player.MoveTo(t, &error)) return JsonError(req, http::status::bad_request, error);
  std::shared_ptr<const std::string> png;
  std::string timing;
  const double load_ms = Ms(t_load, Clock::now());
  if (auto failed = RenderAndStore(service, req, player.state(), q.options, key, *slot.image, &png, &timing))
    return *failed;
  char load[80];
  std::snprintf(load, sizeof load, ", load;dur=%.2f, total;dur=%.2f", load_ms, Ms(t_start, Clock::now()));
  return Png(req, png, etag, kCacheControl, timing + load);
}

ApiResponse Thumbnail(RenderService& service, ApiContext& ctx, ApiRequest& req) {
  const std::string& name = req.params[0];
  int64_t version = 0;
  if (const auto it = req.query.find("version"); it != req.query.end()) {
    const std::string& s = it->second;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), version);
    if (ec != std::errc() || end != s.data() + s.size() || version <= 0)
      return JsonError(req, http::status::bad_request, "version must be a positive integer");
  }
  RenderQuery q;
  std::string error;
  if (!ParseQuery(req, false, kThumbnailSize, &q, &error)) return JsonError(req, http::status::bad_request, error);
  const std::optional<ModelVersion> v = ctx.library->Find(name, version);
  if (!v)
    return JsonError(req, http::status::not_found,
                     "no model '" + name + "'" + (version > 0 ? " version " + std::to_string(version) : ""));
  // A named version never changes; the latest may.
  const char* cache_control = version > 0 ? "private, max-age=31536000, immutable" : "private, no-cache";
  const std::string key = "model|" + v->fem_sha256 + "|" + v->plg_sha256 + "|" + OptionsKey(q.options);
  const std::string etag = "\"" + Sha256Hex(key).substr(0, 32) + "\"";
  if (auto res = NotModified(req, etag, cache_control)) return *res;
  if (auto png = service.Cached(key)) return Png(req, png, etag, cache_control, "cache;desc=hit");
  std::unique_ptr<Image> image = service.TryReserve();
  if (!image) return Busy(req);
  Slot slot{&service, std::move(image)};
  std::string fem, plg;
  if (!ctx.library->blobs().Get(v->fem_sha256, &fem) || !ctx.library->blobs().Get(v->plg_sha256, &plg))
    return JsonError(req, http::status::internal_server_error, "the stored files of " + name + " are missing");
  const auto t_load = Clock::now();
  ViewerState state;
  if (!render::LoadRestStateText(fem, plg, name, &state, &error))
    return JsonError(req, http::status::internal_server_error, "model " + name + ": " + error);
  const double load_ms = Ms(t_load, Clock::now());
  std::shared_ptr<const std::string> png;
  std::string timing;
  if (auto failed = RenderAndStore(service, req, state, q.options, key, *slot.image, &png, &timing)) return *failed;
  char load[48];
  std::snprintf(load, sizeof load, ", load;dur=%.2f", load_ms);
  return Png(req, png, etag, cache_control, timing + load);
}

}  // namespace

void AppendRenderRoutes(ServerCore& core, std::vector<Route>* routes) {
  using P = Permission;
  using V = http::verb;
  auto service = std::make_shared<RenderService>();
  SessionHub* hub = core.hub;
  const std::vector<Route> ours = {
      {V::get, "/api/sessions/{id}/screenshot.png", P::kRead, false, false,
       [service, hub](ApiContext&, ApiRequest& req) { return Screenshot(*service, *hub, req); }, true},
      {V::get, "/api/models/{name}/thumbnail.png", P::kRead, false, false,
       [service](ApiContext& ctx, ApiRequest& req) { return Thumbnail(*service, ctx, req); }, true},
  };
  routes->insert(routes->begin(), ours.begin(), ours.end());
  // Its figures after the others' on /metrics.
  core.ctx.more_metrics = [previous = core.ctx.more_metrics, service] {
    return (previous ? previous() : std::string()) + service->MetricsText();
  };
}

}  // namespace idms::server
