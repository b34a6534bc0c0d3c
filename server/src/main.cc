// idms-server: the session server's command line. `idms-server [options]` serves;
// `idms-server token create ROLE --tokens FILE` adds a token to a tokens file.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "idms/protocol/cli.h"
#include "idms/server/auth.h"
#include "idms/server/bus.h"
#include "idms/server/log.h"
#include "idms/server/postgres.h"
#include "idms/server/server.h"
#include "s3_client.h"

namespace {

using idms::server::ServerOptions;

// "HOST:PORT" or "[V6]:PORT".
bool SplitListen(const std::string& text, std::string* host, uint16_t* port) {
  const size_t colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0) return false;
  std::string h = text.substr(0, colon);
  if (h.size() > 2 && h.front() == '[' && h.back() == ']') h = h.substr(1, h.size() - 2);
  try {
    const int p = std::stoi(text.substr(colon + 1));
    if (p < 0 || p > 65535 || text.substr(colon + 1).find_first_not_of("0123456789") != std::string::npos) return false;
    *host = h;
    *port = static_cast<uint16_t>(p);
  } catch (const std::exception&) {
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  ServerOptions o;
  std::string listen = "127.0.0.1:8740";
  int max_upload_mb = 256, max_ws_mb = 16, header_timeout_s = 15, body_timeout_s = 30, resume_window_s = 600,
      viewer_stall_timeout_s = 10, ws_send_buffer_kb = 256;

  CLI::App app{
      "idms-server: the idms session server. HTTP and WebSocket on one port (TLS optional): the model library "
      "(REST), tokens and roles, /metrics, /api/health.\n"
      "Started on an empty data directory it imports the shipped models/ and, without --tokens, writes one token "
      "per role (admin, agent, observer) to DATA/tokens (mode 0600) and prints that file's path.\n"
      "Signals: SIGTERM/SIGINT stop gracefully (requests in flight finish); SIGHUP reloads the tokens file."};
  app.set_version_flag("--version", idms::Version());
  app.add_option("--listen", listen, "HOST:PORT to listen on (port 0: any free port)")->capture_default_str();
  app.add_option("--data", o.data_dir, "Data directory: idms.db (SQLite), blobs/, tokens")->capture_default_str();
  app.add_option("--store", o.store,
                 "Where the model library, session index, browser logins and session leases live: a PostgreSQL "
                 "database shared by several servers, as postgres://USER@HOST:PORT/DB or a libpq connection "
                 "string (schema migrated at start-up). Default: SQLite in DATA/idms.db, logins in memory")
      ->check([](const std::string& s) {
        return idms::server::IsPostgresConninfo(s) ? std::string()
                                                   : "expected postgres://USER@HOST:PORT/DB or 'host=... dbname=...'";
      });
  const auto s3_url = [](const std::string& s) {
    idms::server::S3Location l;
    std::string error;
    return idms::server::ParseS3Url(s, &l, &error) ? std::string() : error;
  };
  app.add_option("--blobs", o.blobs,
                 "Where the model library's files live: an S3 bucket several servers share, "
                 "s3://HOST:PORT/BUCKET[?region=REGION] (region default us-east-1; &tls=1 for HTTPS), as objects "
                 "blobs/SHA256. Credentials from the environment, AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY, "
                 "never on the command line. Checked at start-up. Default: DATA/blobs/")
      ->check(s3_url);
  app.add_option("--recordings", o.recordings,
                 "Where the sessions' recordings live: an S3 bucket (the same URL form and credentials as --blobs; "
                 "it may be the same bucket). A live recording is written to DATA/recordings/ and uploaded in "
                 "segments as it is written (the agent's ticks are acknowledged once their segment is stored); a "
                 "finished one is the object recordings/ID.mcap, cached in DATA/recordings/ when read. Default: "
                 "DATA/recordings/")
      ->check(s3_url);
  app.add_option("--tokens", o.tokens_file,
                 "Tokens file: 'ROLE TOKEN' or 'ROLE sha256:HEX' per line, # comments (default DATA/tokens)");
  app.add_option("--tls-cert", o.tls_cert, "PEM certificate chain: serve HTTPS and WSS on the same port");
  app.add_option("--tls-key", o.tls_key, "PEM private key for --tls-cert");
  app.add_option("--allowed-origin", o.allowed_origins,
                 "A browser origin besides the server's own that may use cookies and WebSockets (repeatable)");
  app.add_option("--threads", o.threads, "I/O threads (0: the number of cores)")->capture_default_str();
  app.add_option("--workers", o.workers, "Threads for handlers that parse, hash or touch the disk")
      ->capture_default_str();
  app.add_option("--fit-nice", o.fit_nice,
                 "Nice value of the thread that runs model fits (POST /api/sessions/{id}/fit): 0-19, higher "
                 "yields more to everything else")
      ->check(CLI::Range(0, 19))
      ->capture_default_str();
  app.add_option("--log-format", o.log_format, "text or json")
      ->check(CLI::IsMember({"text", "json"}))
      ->capture_default_str();
  app.add_option("--models-dir", o.models_dir,
                 "Models imported into an empty library (default: the shipped models/; 'none': no import)");
#ifdef IDMS_DEFAULT_WEB_ROOT
  o.web_root = IDMS_DEFAULT_WEB_ROOT;
#endif
  app.add_option("--web-root", o.web_root, "The built web viewer served at / (index.html, assets/)")
      ->capture_default_str();
  app.add_option("--max-upload-mb", max_upload_mb, "Largest request body, MiB (413 beyond, before it is read)")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  app.add_option("--max-ws-message-mb", max_ws_mb, "Largest WebSocket message, MiB")
      ->check(CLI::Range(1, 1 << 12))
      ->capture_default_str();
  app.add_option("--max-connections", o.max_connections,
                 "Open connections (HTTP and WebSocket) beyond which new ones get 503")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  app.add_option("--max-connections-per-address", o.max_connections_per_address,
                 "Open connections (HTTP and WebSocket) from one client address, IPv6 by its /64, beyond which "
                 "that address gets 503 while others are still served: one client cannot take the whole "
                 "server. A browser uses about 6 plus its WebSockets; the default leaves three quarters of "
                 "the default --max-connections to everyone else. Behind a reverse proxy every client has the "
                 "proxy's address: 0 (no per-address limit)")
      ->check(CLI::Range(0, 1 << 20))
      ->capture_default_str();
  app.add_option("--header-timeout", header_timeout_s, "Seconds for a whole request header, and keep-alive idle")
      ->check(CLI::Range(1, 3600))
      ->capture_default_str();
  app.add_option("--body-timeout", body_timeout_s, "Seconds for a request body, plus one per MiB announced")
      ->check(CLI::Range(1, 3600))
      ->capture_default_str();

  app.add_option("--resume-window", resume_window_s,
                 "Seconds a live session waits for its agent to come back before it is closed as interrupted")
      ->check(CLI::Range(1, 86400))
      ->capture_default_str();

  app.add_option("--viewer-stall-timeout", viewer_stall_timeout_s,
                 "Seconds a live viewer may stay a full queue behind before it is closed (until then it skips "
                 "mesh deltas and is resynchronised with a keyframe)")
      ->check(CLI::Range(1, 3600))
      ->capture_default_str();

  int agent_idle_timeout_ms = static_cast<int>(o.agent_idle_timeout.count());
  app.add_option("--agent-idle-timeout-ms", agent_idle_timeout_ms,
                 "An agent's link silent this long is dropped (pinged at half of it), so that its resume on a "
                 "new connection is not held up by a dead one")
      ->check(CLI::Range(200, 600000))
      ->capture_default_str();

  app.add_option("--max-live-sessions", o.max_live_sessions,
                 "Live sessions at once; an agent opening one more is refused (resumes are not)")
      ->check(CLI::Range(1, 1 << 16))
      ->capture_default_str();

  app.add_option("--ws-send-buffer-kb", ws_send_buffer_kb,
                 "Kernel send buffer of each WebSocket in KiB (bounds a slow viewer's latency; 0: autotuned)")
      ->check(CLI::Range(0, 65536))
      ->capture_default_str();

  app.add_option("--bus", o.bus,
                 "Several servers: NATS URLs (nats://HOST:PORT, comma-separated) of the bus that carries live "
                 "sessions between them; a viewer of a session another server owns is served here");
  app.add_option("--node", o.node_id,
                 "This server's name among several (the bus, session leases); unique per server (default "
                 "HOSTNAME:PORT)");
  int lease_ttl_ms = static_cast<int>(o.lease_ttl.count());
  app.add_option("--lease-ttl-ms", lease_ttl_ms,
                 "How long a live session's ownership lasts unrenewed (renewed every second): how soon another "
                 "server may take over a session whose owner died")
      ->check(CLI::Range(1500, 600000))
      ->capture_default_str();

  // idms-server token create ROLE --tokens FILE
  CLI::App* token = app.add_subcommand("token", "Manage tokens");
  CLI::App* create =
      token->add_subcommand("create", "Append a new random token's hash to FILE and print the token once");
  std::string role_text, token_file;
  create->add_option("ROLE", role_text, "admin, agent or observer")
      ->required()
      ->check(CLI::IsMember({"admin", "agent", "observer"}));
  create->add_option("--tokens", token_file, "Tokens file (created with mode 0600 when missing)")->required();
  token->require_subcommand(1);

  CLI11_PARSE(app, argc, argv);

  if (create->parsed()) {
    std::string error;
    const std::string t = idms::server::AppendNewToken(token_file, idms::server::ParseRole(role_text), &error);
    if (t.empty()) {
      std::fprintf(stderr, "idms-server: %s\n", error.c_str());
      return 1;
    }
    std::printf("%s\n", t.c_str());
    return 0;
  }

  if (!SplitListen(listen, &o.host, &o.port)) {
    std::fprintf(stderr, "idms-server: --listen '%s': expected HOST:PORT\n", listen.c_str());
    return 2;
  }
  o.max_upload_bytes = int64_t{max_upload_mb} << 20;
  o.max_ws_message_bytes = int64_t{max_ws_mb} << 20;
  o.header_timeout = std::chrono::seconds(header_timeout_s);
  o.body_timeout = std::chrono::seconds(body_timeout_s);
  o.resume_window = std::chrono::seconds(resume_window_s);
  o.viewer_stall_timeout = std::chrono::seconds(viewer_stall_timeout_s);
  o.agent_idle_timeout = std::chrono::milliseconds(agent_idle_timeout_ms);
  o.lease_ttl = std::chrono::milliseconds(lease_ttl_ms);
  o.ws_send_buffer_bytes = ws_send_buffer_kb << 10;
  idms::server::SetLogFormat(o.log_format);

  int status = 0;
  {
    idms::server::Server server(o);
    std::string error;
    if (!server.Start(&error)) {
      std::fprintf(stderr, "idms-server: %s\n", error.c_str());
      status = 1;
    } else {
      const char* scheme = o.tls_cert.empty() ? "http" : "https";
      // Machine-readable first line (tests and scripts wait for it), then where the tokens are.
      std::printf("idms-server listening on %s://%s:%u\n", scheme, o.host.c_str(), server.port());
      std::printf("tokens: %s\n", server.tokens_path().c_str());
      std::fflush(stdout);
      status = server.Run();
    }
  }
  if (!o.bus.empty()) idms::server::CloseBusLibrary();  // after the server and its bus are gone
  return status;
}
