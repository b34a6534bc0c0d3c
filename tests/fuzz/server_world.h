// What the server's WebSocket fuzz targets share (ws_fuzz, replay_fuzz): a server core without
// sockets over a temporary data directory, its WebSocket routes, a peer that checks every frame
// the server sends is an Envelope, and a way to run everything posted until it has run.
#pragma once

#include <unistd.h>

#include <boost/asio/post.hpp>
#include <filesystem>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include "../../server/src/server_internal.h"
#include "../../server/src/sessions.h"
#include "../../server/src/ws_endpoint.h"
#include "idms/protocol/envelope.h"
#include "idms/server/library.h"
#include "idms/server/storage.h"

namespace idms::fuzz {

// A connection as an endpoint sees it. Send may run on a worker (a replay's strand).
class FuzzPeer final : public server::WsPeer {
 public:
  explicit FuzzPeer(std::string name) : name_(std::move(name)) {}
  void Send(std::shared_ptr<const std::string> message, bool binary) override {
    v1::Envelope e;
    std::string error;
    if (!binary || !ParseEnvelope(*message, &e, &error)) __builtin_trap();  // the server speaks Envelopes
    if (e.has_welcome()) {
      welcome_session = e.welcome().session_id();
      if (!e.welcome().resume_token().empty()) welcome_token = e.welcome().resume_token();
    }
  }
  void Close(uint16_t, std::string) override { closed = true; }
  size_t queued() const override { return 0; }
  size_t queued_bytes() const override { return 0; }
  const std::string& peer() const override { return name_; }

  std::atomic<bool> closed{false};
  std::string welcome_session, welcome_token;  // from the last Welcome (the session's strand)

 private:
  std::string name_;
};

struct ServerWorld {
  std::string dir;
  server::Storage storage;
  std::unique_ptr<server::Library> library;
  server::ServerCore core{server::ServerOptions{}, 1, 1};
  std::unique_ptr<server::LeaseStore> leases = server::MakeMemoryLeaseStore();
  std::unique_ptr<server::SessionHub> hub;
  std::vector<server::Route> routes;

  explicit ServerWorld(const std::string& name)
      : dir((std::filesystem::temp_directory_path() / (name + "-" + std::to_string(::getpid()))).string()) {
    std::filesystem::remove_all(dir);
    std::string error;
    if (!server::OpenStorage(dir, &storage, &error)) __builtin_trap();
    library = std::make_unique<server::Library>(storage.blobs.get(), storage.models.get());
    core.ctx.options = &core.options;
    core.ctx.library = library.get();
    core.ctx.metrics = &core.metrics;
    core.leases = leases.get();
    core.options.node_id = "fuzz";
    hub = std::make_unique<server::SessionHub>(core, storage.sessions.get(), storage.recordings.get());
    core.hub = hub.get();
    server::AppendWebSocketRoutes(core, &routes);
  }

  // The endpoint of a WebSocket route, as an admitted upgrade would get it (null: refused).
  std::shared_ptr<server::WsEndpoint> Open(const std::string& pattern, std::vector<std::string> params,
                                           server::Role role) {
    server::ApiRequest req;
    req.path = pattern;
    req.params = std::move(params);
    req.role = role;
    std::string refusal;
    for (const server::Route& r : routes) {
      if (r.pattern == pattern) return r.open_websocket(req, &refusal);
    }
    return nullptr;
  }

  // The sessions' strands, then the recorder's and the workers' queues, until what was posted has run.
  void RunPosted() {
    for (int round = 0; round < 4; ++round) {
      core.ioc.restart();
      core.ioc.poll();
      std::promise<void> recorded, worked;
      boost::asio::post(core.recorder, [&] { recorded.set_value(); });
      recorded.get_future().wait();
      boost::asio::post(core.workers, [&] { worked.set_value(); });
      worked.get_future().wait();
    }
  }
};

inline std::string Frame(const v1::Envelope& e) {
  std::string bytes;
  SerializeEnvelope(e, &bytes);
  return bytes;
}

}  // namespace idms::fuzz
