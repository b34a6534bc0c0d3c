// libFuzzer target: the server's request path, from raw bytes. Beast parses the message; then
// admission (target, route, bearer or cookie, role, Origin, size, media type) and the handler
// run as the server runs them, uploads included (JSON and multipart bodies, the fem/plg
// parsers), against in-memory stores, which also shows that the storage interfaces are enough
// for the HTTP code. Any input must give a well-formed response, never a crash or a leak.
#include <boost/beast/http.hpp>
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <variant>

#include "idms/server/api.h"

namespace {

namespace http = boost::beast::http;
using namespace idms::server;

class MemoryBlobs final : public BlobStore {
 public:
  bool Put(std::string_view bytes, std::string* sha, std::string*) override {
    *sha = Sha256Hex(bytes);
    blobs_[*sha] = std::string(bytes);
    return true;
  }
  bool Get(const std::string& sha, std::string* bytes) const override {
    const auto it = blobs_.find(sha);
    if (it == blobs_.end()) return false;
    *bytes = it->second;
    return true;
  }
  bool Has(const std::string& sha) const override { return blobs_.count(sha) != 0; }
  void Remove(const std::string& sha) override { blobs_.erase(sha); }
  std::vector<std::string> List() const override {
    std::vector<std::string> out;
    for (const auto& [k, v] : blobs_) out.push_back(k);
    return out;
  }
  void Clear() { blobs_.clear(); }

 private:
  std::map<std::string, std::string> blobs_;
};

class MemoryModels final : public ModelStore {
 public:
  std::vector<ModelVersion> ListLatest() override {
    std::vector<ModelVersion> out;
    for (const auto& [name, rec] : models_) {
      if (!rec.versions.empty()) out.push_back(rec.latest());
    }
    return out;
  }
  std::optional<ModelRecord> Get(const std::string& name) override {
    const auto it = models_.find(name);
    if (it == models_.end() || it->second.versions.empty()) return std::nullopt;
    return it->second;
  }
  bool AddVersion(ModelVersion* v, std::string*) override {
    ModelRecord& rec = models_[v->name];
    rec.name = v->name;
    v->version = ++next_[v->name];
    rec.versions.push_back(*v);
    return true;
  }
  bool Delete(const std::string& name, int64_t version) override {
    const auto it = models_.find(name);
    if (it == models_.end()) return false;
    auto& vs = it->second.versions;
    const size_t before = vs.size();
    std::erase_if(vs, [&](const ModelVersion& v) { return version == 0 || v.version == version; });
    return vs.size() != before;
  }
  bool BlobReferenced(const std::string& sha) override {
    for (const auto& [name, rec] : models_) {
      for (const ModelVersion& v : rec.versions) {
        if (v.fem_sha256 == sha || v.plg_sha256 == sha || v.obj_sha256 == sha) return true;
      }
    }
    return false;
  }
  int64_t NumModels() override { return static_cast<int64_t>(ListLatest().size()); }
  int64_t LibraryBytes() override { return 0; }
  void Clear() { models_.clear(), next_.clear(); }

 private:
  std::map<std::string, ModelRecord> models_;
  std::map<std::string, int64_t> next_;
};

struct World {
  MemoryBlobs blobs;
  MemoryModels models;
  Library library{&blobs, &models};
  ServerOptions options;
  MemoryLoginSessions logins{std::chrono::seconds(3600)};
  Metrics metrics;
  std::shared_ptr<const TokenTable> tokens;
  ApiContext ctx;
  std::vector<Route> routes = MakeRoutes();

  World() {
    auto t = std::make_shared<TokenTable>();
    std::string error;
    TokenTable::Parse("admin fuzz-admin-token-0001\nagent fuzz-agent-token-0001\nobserver fuzz-observer-token-01\n",
                      "fuzz", t.get(), &error);
    tokens = t;
    options.max_upload_bytes = 1 << 20;
    options.allowed_origins = {"https://lab.example"};
    ctx.options = &options;
    ctx.library = &library;
    ctx.logins = &logins;
    ctx.metrics = &metrics;
    ctx.tokens = [this] { return tokens; };
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = new World();
  world->blobs.Clear();
  world->models.Clear();
  // Beast parses the message as the server's connection does (header and body limits).
  http::request_parser<http::string_body> parser;
  parser.eager(true);
  parser.header_limit(16 << 10);
  parser.body_limit(1 << 20);
  boost::beast::error_code ec;
  parser.put(boost::asio::buffer(data, size), ec);
  if (ec == http::error::need_more) parser.put_eof(ec);
  if (ec || !parser.is_done()) return 0;
  ApiRequest req;
  req.message = parser.release();
  Admission a = Admit(world->ctx, world->routes, req);
  unsigned status = 0;
  if (a.error) {
    status = a.error->result_int();
  } else if (a.route->handler) {
    const HandlerResponse res = a.route->handler(world->ctx, req);
    status = std::visit([](const auto& r) { return r.result_int(); }, res);
    // A successful upload is in the library, whole.
    if (status == 201 && !world->library.Find(req.params[0], 0)) __builtin_trap();
  } else {
    return 0;  // a WebSocket upgrade: the connection code takes over
  }
  if (status < 200 || status > 599) __builtin_trap();
  return 0;
}
