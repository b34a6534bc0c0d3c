// idms-server's settings, as its command line sets them.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace idms::server {

struct ServerOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 8740;  // 0: any free port (printed at start-up)
  std::string data_dir = "./idms-data";
  // Empty: the model library and session index in DATA/idms.db (SQLite), logins and leases in
  // memory. A postgres:// URL or libpq connection string: all four in that database.
  std::string store;
  // Empty: the library's blobs in DATA/blobs/, the recordings in DATA/recordings/. An
  // s3://HOST:PORT/BUCKET[?region=R] URL: in that bucket (credentials from AWS_ACCESS_KEY_ID and
  // AWS_SECRET_ACCESS_KEY), under blobs/ and recordings/ (the same bucket may serve both).
  std::string blobs, recordings;
  std::string tokens_file;                   // empty: DATA/tokens, created with one token per role
  std::string tls_cert, tls_key;             // both or neither: TLS on the same port
  std::vector<std::string> allowed_origins;  // besides the server's own, e.g. "https://lab.example"
  int threads = 0;                           // I/O threads; 0: the number of cores
  int workers = 4;                           // threads for handlers that parse, hash or touch the disk
  int fit_nice = 10;                         // the fit jobs' thread's nice value (0-19): below sessions
  std::string log_format = "text";           // text | json
  std::string models_dir;                    // shipped models to import into an empty library; "none": never
  std::string web_root;                      // the built web viewer (index.html, assets/); empty: none served
  int64_t max_upload_bytes = int64_t{256} << 20;
  int64_t max_small_body_bytes = int64_t{64} << 10;  // every route but uploads
  int64_t max_ws_message_bytes = int64_t{16} << 20;
  uint32_t max_header_bytes = 16 << 10;
  int max_connections = 1024;  // HTTP and WebSocket; beyond: 503 and close
  // From one client address (IPv6: one /64); beyond: 503 for that address, the others still served.
  // 0: no limit (behind a reverse proxy every client has the proxy's address).
  int max_connections_per_address = 256;
  int max_concurrent_uploads = 2;           // bodies over 1 MiB at once; beyond: 503 + Retry-After
  std::chrono::seconds header_timeout{15};  // a whole request header, and the keep-alive idle time
  std::chrono::seconds body_timeout{30};    // plus 1 s per MiB of the announced body
  std::chrono::seconds login_lifetime{12 * 3600};
  std::chrono::seconds shutdown_grace{10};  // SIGTERM: requests in flight get this long
  // A live session whose agent has been gone this long is closed as "interrupted" (recording
  // finished); its agent can still resume it later, as after a restart.
  std::chrono::seconds resume_window{600};
  // A live viewer that stays this long more than a queue's worth of frames behind is closed.
  std::chrono::seconds viewer_stall_timeout{10};
  // An agent's WebSocket silent this long (no frame, no pong) is dropped; pinged at half of it.
  // Short, so that a dead link is noticed within 2 s and the agent's resume is not held up.
  std::chrono::milliseconds agent_idle_timeout{2000};
  // Live sessions at once (each holds a recorder, a mirror and its viewers); a new one beyond is
  // refused with a reason, resumes of sessions live here are not.
  int max_live_sessions = 256;
  // SO_SNDBUF of every WebSocket: a fixed kernel send buffer instead of Linux's autotuning (up to
  // 4 MiB), so that a slow peer's backlog builds in the server's queue, where deltas are skipped
  // and keyframes resynchronise, not as seconds of stale frames in the kernel. 0: the system's.
  int ws_send_buffer_bytes = 256 << 10;
  // Several servers (docs: "Several servers"): the bus between them (NATS URLs, comma-separated;
  // empty: this server alone) and this server's name on it (empty: HOST:PORT once bound).
  std::string bus;
  std::string node_id;
  // Each live session is owned through a lease (LeaseStore) renewed once a second: the owner
  // publishes, records and acknowledges only while it holds it, and another server can take the
  // session over (its agent resuming there) once it has lapsed. Viewers of a dead owner freeze
  // for about this long; the database may be down for any time without the owner letting go.
  std::chrono::milliseconds lease_ttl{5000};
};

}  // namespace idms::server
