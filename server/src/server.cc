// The server's life: data directory and library import, tokens (created on first start, reloaded
// on SIGHUP), TLS, the listener, the I/O threads, and a graceful stop on SIGTERM / SIGINT.
#include "idms/server/server.h"

#include <openssl/ssl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <boost/asio/ip/host_name.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core/error.hpp>
#include <cerrno>
#include <filesystem>
#include <thread>

#include "fit_jobs.h"
#include "idms/server/bus.h"
#include "idms/server/log.h"
#include "idms/server/postgres.h"
#include "render_api.h"
#include "s3_stores.h"
#include "server_internal.h"
#include "sessions.h"

namespace idms::server {

namespace asio = boost::asio;
namespace fs = std::filesystem;
using tcp = asio::ip::tcp;

struct Server::Impl {
  explicit Impl(const ServerOptions& o)
      : core(o, ResolveThreads(o.threads), std::max(1, o.workers)),
        acceptor(asio::make_strand(core.ioc)),
        accept_pause(acceptor.get_executor()),
        signals(core.ioc, SIGINT, SIGTERM, SIGHUP),
        grace(acceptor.get_executor()) {}

  static int ResolveThreads(int n) { return n > 0 ? n : std::max(1u, std::thread::hardware_concurrency()); }

  bool Start(std::string* error);
  bool LoadTokens(std::string* error);
  void DoAccept();
  void WaitSignal();
  void Stop();

  ServerCore core;
  Storage storage;
  std::unique_ptr<Library> library;
  std::unique_ptr<Bus> bus;  // before the hub: its sessions' subscriptions go first
  std::unique_ptr<SessionHub> hub;
  std::shared_ptr<FitJobs> fits;  // POST /api/sessions/{id}/fit
  std::unique_ptr<LoginSessions> logins;
  std::unique_ptr<LeaseStore> leases;
  std::mutex tokens_mu;
  std::shared_ptr<const TokenTable> tokens = std::make_shared<TokenTable>();
  std::string tokens_path;
  tcp::acceptor acceptor;
  asio::steady_timer accept_pause;  // on the acceptor's strand
  bool accept_paused = false;       // logged once per run of failures
  asio::signal_set signals;
  asio::steady_timer grace;  // on the acceptor's strand
  uint16_t port = 0;
  int threads = 1;
};

namespace {

// How long the accept loop waits after running out of descriptors or memory. Long enough not to
// spin (a failed accept costs microseconds), short against a connection's lifetime.
constexpr std::chrono::milliseconds kAcceptPause{100};

// EMFILE, ENFILE, ENOBUFS, ENOMEM: accepting again now would fail again now.
bool OutOfResources(const boost::system::error_code& ec) {
  if (ec.category() != boost::system::system_category()) return false;
  const int e = ec.value();
  return e == EMFILE || e == ENFILE || e == ENOBUFS || e == ENOMEM;
}

constexpr const char* kTls12Suites =
    "ECDHE-ECDSA-AES128-GCM-SHA256:ECDHE-RSA-AES128-GCM-SHA256:ECDHE-ECDSA-AES256-GCM-SHA384:"
    "ECDHE-RSA-AES256-GCM-SHA384:ECDHE-ECDSA-CHACHA20-POLY1305:ECDHE-RSA-CHACHA20-POLY1305";

// The shipped models/ directory: $IDMS_MODELS_DIR, beside the build (build/bin/../../models), an
// installed share/idms/models, or the source tree this binary was built from.
std::string FindShippedModels() {
  if (const char* env = std::getenv("IDMS_MODELS_DIR"); env != nullptr && *env != '\0') return env;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  std::vector<fs::path> candidates;
  if (!ec) {
    candidates.push_back(exe.parent_path() / ".." / ".." / "models");
    candidates.push_back(exe.parent_path() / ".." / "share" / "idms" / "models");
  }
#ifdef IDMS_SOURCE_MODELS_DIR
  candidates.emplace_back(IDMS_SOURCE_MODELS_DIR);
#endif
  for (const fs::path& c : candidates) {
    if (fs::exists(c / "hex_4x5_home.fem", ec)) return fs::weakly_canonical(c, ec).string();
  }
  return {};
}

// --blobs and --recordings: S3 buckets (the same one may serve both), checked now (an unreachable store, a missing
// bucket or refused credentials stop the start, naming the problem). Credentials from the environment.
bool OpenObjectStores(const ServerOptions& o, ObjectStores* objects, std::string* error) {
  if (o.blobs.empty() && o.recordings.empty()) return true;
  S3Credentials credentials;
  if (!S3CredentialsFromEnvironment(&credentials, error)) return false;
  if (!o.blobs.empty()) {
    S3Location l;
    if (!ParseS3Url(o.blobs, &l, error) || !(objects->blobs = OpenS3BlobStore(l, credentials, error))) {
      *error = "--blobs: " + *error;
      return false;
    }
    Log(LogLevel::kInfo, "blobs in object storage", {{"blobs", l.Describe() + "/blobs/"}});
  }
  if (!o.recordings.empty()) {
    // The live files and a cache of finished ones stay in DATA/recordings/.
    S3Location l;
    const std::string cache = (fs::path(o.data_dir) / "recordings").string();
    if (!ParseS3Url(o.recordings, &l, error) ||
        !(objects->recordings = OpenS3RecordingStore(l, credentials, cache, error))) {
      *error = "--recordings: " + *error;
      return false;
    }
    Log(LogLevel::kInfo, "recordings in object storage", {{"recordings", l.Describe() + "/recordings/"}});
  }
  return true;
}

}  // namespace

bool Server::Impl::LoadTokens(std::string* error) {
  auto table = std::make_shared<TokenTable>();
  if (!TokenTable::Load(tokens_path, table.get(), error)) return false;
  std::lock_guard lock(tokens_mu);
  tokens = std::move(table);
  return true;
}

bool Server::Impl::Start(std::string* error) {
  const ServerOptions& o = core.options;
  // Storage (SQLite and files, or PostgreSQL and files with --store), and the shipped library on
  // first start.
  ObjectStores objects;
  if (!OpenObjectStores(o, &objects, error)) return false;
  if (o.store.empty()) {
    if (!OpenStorage(o.data_dir, &storage, error, std::move(objects))) return false;
    logins = std::make_unique<MemoryLoginSessions>(o.login_lifetime);
    leases = MakeMemoryLeaseStore();
  } else {
    PostgresStores pg;
    // One connection per worker and two for the I/O threads' login lookups.
    if (!OpenPostgres(o.store, o.login_lifetime, std::max(1, o.workers) + 2, &pg, error) ||
        !OpenStorage(o.data_dir, std::move(pg.models), std::move(pg.sessions), &storage, error, std::move(objects)))
      return false;
    logins = std::move(pg.logins);
    leases = std::move(pg.leases);
    Log(LogLevel::kInfo, "models, sessions, logins and leases in PostgreSQL",
        {{"schema_version", PostgresSchemaVersion()}});
  }
  library = std::make_unique<Library>(storage.blobs.get(), storage.models.get());
  if (storage.models->NumModels() == 0 && o.models_dir != "none") {
    const std::string dir = o.models_dir.empty() ? FindShippedModels() : o.models_dir;
    if (!dir.empty()) {
      const int n = library->ImportDirectory(dir, error);
      if (n < 0) return false;
      Log(LogLevel::kInfo, "imported the shipped models", {{"count", n}, {"from", dir}});
    } else {
      Log(LogLevel::kWarn, "no shipped models found to import (set --models-dir)");
    }
  }
  // Tokens: the given file, else DATA/tokens (created with one token per role).
  tokens_path = o.tokens_file.empty() ? (fs::path(o.data_dir) / "tokens").string() : o.tokens_file;
  if (o.tokens_file.empty() && !fs::exists(tokens_path)) {
    if (!CreateDefaultTokens(tokens_path, error)) return false;
    Log(LogLevel::kInfo, "created one token per role (admin, agent, observer)", {{"file", tokens_path}});
  }
  if (!LoadTokens(error)) return false;
  // TLS on the same port when asked.
  if (o.tls_cert.empty() != o.tls_key.empty()) {
    *error = "--tls-cert and --tls-key go together";
    return false;
  }
  if (!o.tls_cert.empty()) {
    core.tls.emplace(asio::ssl::context::tls_server);
    boost::system::error_code ec;
    core.tls->set_options(asio::ssl::context::default_workarounds | asio::ssl::context::no_sslv2 |
                          asio::ssl::context::no_sslv3 | asio::ssl::context::no_tlsv1 | asio::ssl::context::no_tlsv1_1);
    // TLS 1.2: forward-secret AEAD suites only (Mozilla's "intermediate" without finite-field
    // DHE, slow and needing parameters): no static-RSA key exchange, no CBC. TLS 1.3 keeps
    // OpenSSL's suites, all of which are. No client-initiated renegotiation (a CPU sink).
    SSL_CTX_set_options(core.tls->native_handle(), SSL_OP_NO_RENEGOTIATION);
    if (SSL_CTX_set_cipher_list(core.tls->native_handle(), kTls12Suites) != 1) {
      *error = "this OpenSSL offers none of the TLS 1.2 suites " + std::string(kTls12Suites);
      return false;
    }
    if (core.tls->use_certificate_chain_file(o.tls_cert, ec); ec) {
      *error = "--tls-cert " + o.tls_cert + ": " + ec.message();
      return false;
    }
    if (core.tls->use_private_key_file(o.tls_key, asio::ssl::context::pem, ec); ec) {
      *error = "--tls-key " + o.tls_key + ": " + ec.message();
      return false;
    }
  }
  // The API context.
  core.ctx.options = &core.options;
  core.ctx.library = library.get();
  core.ctx.logins = logins.get();
  core.leases = leases.get();
  core.ctx.metrics = &core.metrics;
  core.ctx.tokens = [this] {
    std::lock_guard lock(tokens_mu);
    return tokens;
  };
  core.ctx.publish_library_event = [this](std::string text) { core.Publish(text); };
  core.ctx.more_metrics = [this] { return hub->MetricsText() + (fits ? FitMetrics(*fits) : std::string()); };
  hub = std::make_unique<SessionHub>(core, storage.sessions.get(), storage.recordings.get());
  core.hub = hub.get();
  core.routes = MakeRoutes();
  AppendWebSocketRoutes(core, &core.routes);
  AppendSessionRoutes(core, &core.routes);
  AppendRenderRoutes(core, &core.routes);
  fits = AppendFitRoutes(core, &core.routes);
  AnswerStoreFailures(&core.routes, !o.store.empty() || !o.blobs.empty() || !o.recordings.empty());
  // On the acceptor's strand, where Stop arms the timer: a connection's last close on another
  // I/O thread must not cancel it while Stop is setting it (a race TSan found).
  core.on_last_connection_closed = [this] { asio::post(acceptor.get_executor(), [this] { grace.cancel(); }); };
  // Bind.
  boost::system::error_code ec;
  const auto address = asio::ip::make_address(o.host, ec);
  if (ec) {
    *error = "--listen: '" + o.host + "' is not an IP address";
    return false;
  }
  const tcp::endpoint endpoint(address, o.port);
  acceptor.open(endpoint.protocol(), ec);
  if (!ec) acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) acceptor.bind(endpoint, ec);
  if (!ec) acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    *error = "cannot listen on " + o.host + ":" + std::to_string(o.port) + ": " + ec.message();
    return false;
  }
  port = acceptor.local_endpoint().port();
  // Node names must differ between servers (they hold leases): the host's name, not the
  // listening address (0.0.0.0 on every container).
  if (core.options.node_id.empty()) {
    boost::system::error_code host_ec;
    const std::string host = asio::ip::host_name(host_ec);
    core.options.node_id = (host_ec || host.empty() ? o.host : host) + ":" + std::to_string(port);
  }
  // After the node has its name: a live session another server holds is not this one's to repair.
  hub->RecoverInterrupted();
  if (!o.bus.empty()) {
    bus = OpenNatsBus(o.bus, core.options.node_id, error);
    if (!bus) return false;
    hub->SetBus(bus.get());
    Log(LogLevel::kInfo, "on the bus", {{"bus", o.bus}, {"node", core.options.node_id}});
  }
  threads = ResolveThreads(o.threads);
  return true;
}

void Server::Impl::DoAccept() {
  acceptor.async_accept(asio::make_strand(core.ioc), [this](boost::system::error_code ec, AcceptedSocket socket) {
    if (ec == asio::error::operation_aborted || !acceptor.is_open()) return;
    if (!ec) {
      accept_paused = false;
      Launch(core, std::move(socket));
      return DoAccept();
    }
    if (!OutOfResources(ec)) return DoAccept();  // this client gave up (ECONNABORTED): the next one
    // Out of descriptors or memory: a new attempt would fail at once, and the loop would spin a
    // core while nobody is served. Pause: the open connections are served meanwhile, and the
    // clients wait in the listen queue until one of them closes.
    ++core.metrics.accept_paused;
    if (!accept_paused) {
      Log(LogLevel::kWarn, "cannot accept; pausing until a connection closes",
          {{"error", ec.message()}, {"retry_ms", kAcceptPause.count()}});
    }
    accept_paused = true;
    accept_pause.expires_after(kAcceptPause);
    accept_pause.async_wait([this](boost::system::error_code wait_ec) {
      if (!wait_ec && acceptor.is_open()) DoAccept();
    });
  });
}

void Server::Impl::WaitSignal() {
  signals.async_wait([this](boost::system::error_code ec, int signal) {
    if (ec) return;
    if (signal == SIGHUP) {
      std::string error;
      if (LoadTokens(&error)) {
        Log(LogLevel::kInfo, "reloaded the tokens file", {{"file", tokens_path}});
      } else {
        Log(LogLevel::kError, "tokens file not reloaded; the previous tokens stay in force", {{"error", error}});
      }
      return WaitSignal();
    }
    Log(LogLevel::kInfo, "stopping", {{"signal", signal == SIGINT ? "SIGINT" : "SIGTERM"}});
    Stop();
  });
}

void Server::Impl::Stop() {
  asio::post(acceptor.get_executor(), [this] {
    if (core.draining.exchange(true)) return;
    boost::system::error_code ignored;
    acceptor.close(ignored);
    accept_pause.cancel();
    signals.cancel(ignored);
    // Sessions first: their recordings are finished and they are marked interrupted (an agent
    // may resume them after a restart); then every connection drains.
    hub->StopAll();
    StopFits(*fits);
    // Requests in flight get the grace period; then the I/O threads stop regardless.
    grace.expires_after(core.options.shutdown_grace);
    grace.async_wait([this](boost::system::error_code ec) {
      if (!ec) core.ioc.stop();
    });
    core.DrainAll();
  });
}

Server::Server(ServerOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}
Server::~Server() = default;

bool Server::Start(std::string* error) { return impl_->Start(error); }
uint16_t Server::port() const { return impl_->port; }
const std::string& Server::tokens_path() const { return impl_->tokens_path; }
void Server::Stop() { impl_->Stop(); }

int Server::Run() {
  impl_->DoAccept();
  impl_->WaitSignal();
  std::vector<std::thread> extra;
  for (int i = 1; i < impl_->threads; ++i) extra.emplace_back([this] { impl_->core.ioc.run(); });
  impl_->core.ioc.run();
  for (std::thread& t : extra) t.join();
  // Recordings finished first (their last rows go to the workers), then handlers and index writes
  // still on a worker finish before the database closes.
  impl_->core.recorder.join();
  impl_->core.workers.join();
  JoinFits(*impl_->fits);
  Log(LogLevel::kInfo, "stopped");
  return 0;
}

}  // namespace idms::server
