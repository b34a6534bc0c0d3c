// What idms-server keeps, behind small interfaces of its own: file contents by SHA-256
// (BlobStore) and the model library's metadata (ModelStore). The HTTP code sees only these, so a
// PostgreSQL / object-storage pair can replace the SQLite / directory pair without touching it.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "idms/protocol/digest.h"

namespace idms::server {

// Thrown by any method of a store whose database cannot be reached (PostgreSQL stopped or
// restarting): the HTTP request that needed it is answered 503 with Retry-After, never 500. The
// next call reconnects by itself. The SQLite stores and the files never throw it. Methods that
// return false with *error keep doing so for everything else (a taken note id, ...).
class StoreUnavailable : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Content-addressed files. Thread-safe.
class BlobStore {
 public:
  virtual ~BlobStore() = default;
  // Stores `bytes` (no-op when already present) and returns its SHA-256 as 64 lowercase hex
  // digits in *sha. Durable on return: written to a temporary file, fsync'ed and renamed.
  virtual bool Put(std::string_view bytes, std::string* sha, std::string* error) = 0;
  // The whole blob; false when absent or unreadable.
  virtual bool Get(const std::string& sha, std::string* bytes) const = 0;
  virtual bool Has(const std::string& sha) const = 0;
  virtual void Remove(const std::string& sha) = 0;
  // Every stored hash (for garbage collection at start-up).
  virtual std::vector<std::string> List() const = 0;
};

// Everything the library says about one version of a model.
struct ModelVersion {
  std::string name;
  int64_t version = 0;  // 1, 2, ...: never reused for a name, even after a delete
  std::string description;
  std::string created;  // UTC, ISO 8601 ("2026-11-23T19:04:05Z")
  int64_t atoms = 0, elements = 0, triangles = 0;
  int64_t bytes = 0;  // fem + plg
  std::string fem_sha256, plg_sha256, obj_sha256;
  // A JSON object about how this version was made (a fit's report: POST /api/sessions/{id}/fit),
  // at most kMaxVersionMetadataBytes; empty for an upload. Read by ModelStore::Get only (the
  // list of latest versions leaves it empty: it is a page's worth, not a line's).
  std::string metadata;
};
inline constexpr size_t kMaxVersionMetadataBytes = 64 * 1024;

// A model and its versions, oldest first.
struct ModelRecord {
  std::string name;
  std::vector<ModelVersion> versions;
  const ModelVersion& latest() const { return versions.back(); }
};

// The library's metadata. Thread-safe. Blobs named here must already be durable in the
// BlobStore when AddVersion is called (the crash-safety order: blob, then row).
class ModelStore {
 public:
  virtual ~ModelStore() = default;
  // Every model with at least one version, by name, each with only its latest version.
  virtual std::vector<ModelVersion> ListLatest() = 0;
  virtual std::optional<ModelRecord> Get(const std::string& name) = 0;
  // Adds the next version of `v.name` in one transaction; sets v.version and returns it.
  virtual bool AddVersion(ModelVersion* v, std::string* error) = 0;
  // Deletes one version (version > 0) or the whole model (version 0). False when absent.
  virtual bool Delete(const std::string& name, int64_t version) = 0;
  // Whether any version still names `sha` (as fem, plg or obj).
  virtual bool BlobReferenced(const std::string& sha) = 0;
  virtual int64_t NumModels() = 0;
  virtual int64_t LibraryBytes() = 0;  // fem + plg bytes over all stored versions
};

// One session as the index keeps it: what the session list shows, and what a resume needs.
struct SessionRow {
  std::string id;
  std::string state;  // "live", "ended" or "interrupted" (the server stopped under it)
  std::string model, device, identity;
  std::string started;        // UTC, ISO 8601
  double duration_s = 0;      // first to last recorded sample
  int64_t samples = 0;        // device samples recorded
  uint64_t next_tick = 0;     // the first tick not recorded yet (a resume starts there)
  std::string resume_sha256;  // hex digest of the agent's resume token; the token itself is never stored
  std::string recording;      // file name under DATA/recordings/
  std::string summary_json;   // the session's summary figures (peak force, time in contact, ...)
  std::string scene_text;     // the agent's scene, protobuf text format
  std::string trainee;        // who was at the device (Hello.trainee; an admin may correct it)
};

// A note added to a session once its recording was finished (during a replay): the notes made
// while it was live are in the recording itself. Ids continue the session's own (1, 2, ...).
struct SessionNote {
  uint64_t id = 0;
  double time_s = 0;    // the session time it refers to, s
  std::string text;     // 1 to 1000 bytes of UTF-8
  std::string author;   // the role and address that added it
  std::string created;  // UTC, ISO 8601
};

// The session index. Thread-safe.
class SessionIndex {
 public:
  virtual ~SessionIndex() = default;
  virtual bool Put(const SessionRow& row, std::string* error) = 0;  // insert or replace by id
  virtual std::optional<SessionRow> Get(const std::string& id) = 0;
  virtual std::vector<SessionRow> List() = 0;      // newest first
  virtual bool Delete(const std::string& id) = 0;  // the row and its notes
  // Stores `row` (its summary carries the notes counter) and `note` together, or neither.
  virtual bool PutWithNote(const SessionRow& row, const SessionNote& note, std::string* error) = 0;
  virtual std::vector<SessionNote> Notes(const std::string& id) = 0;  // by id
};

// The owner of a live session, among several servers: a lease that its holder renews, and an
// epoch (fencing token) that grows every time the lease is taken, so that whatever an old owner
// still sends (stamped with its epoch) can be told from the new owner's. Expiry is judged by one
// clock (the database's, for PostgreSQL), never by the nodes' own. Thread-safe; called from
// worker threads, never from the 1 kHz loop (each call may be a database round trip).
struct Lease {
  std::string holder;                      // the node id
  int64_t epoch = 0;                       // 1, 2, ...: strictly increasing per session, never reused
  std::chrono::milliseconds remaining{0};  // until it expires, by the store's clock
};
class LeaseStore {
 public:
  virtual ~LeaseStore() = default;
  // Takes the lease on `session_id` for `node_id` for `ttl` when nobody holds it, its holder's
  // lease has expired, or `node_id` holds it already. Returns the new epoch (the previous epoch
  // + 1, or 1 for a session never leased; a node that takes its own lease again gets a new epoch
  // too, fencing its previous incarnation); nullopt while another node holds it.
  virtual std::optional<int64_t> Acquire(const std::string& session_id, const std::string& node_id,
                                         std::chrono::milliseconds ttl) = 0;
  // Extends the lease by `ttl` from now. False when it is lost: expired (even if nobody took it
  // since: its holder must Acquire again, for a new epoch), taken by another node, or released.
  virtual bool Renew(const std::string& session_id, const std::string& node_id, int64_t epoch,
                     std::chrono::milliseconds ttl) = 0;
  // Gives the lease up at once (the epoch stays: the next Acquire gets epoch + 1). No-op unless
  // (node_id, epoch) holds it.
  virtual void Release(const std::string& session_id, const std::string& node_id, int64_t epoch) = 0;
  // The holder of an unexpired lease; nullopt when nobody holds it.
  virtual std::optional<Lease> Holder(const std::string& session_id) = 0;
};
// Leases in this process (the single-server default): the same rules by the steady clock.
std::unique_ptr<LeaseStore> MakeMemoryLeaseStore();

// Where the sessions' recordings are kept: each session's MCAP file is written live under one
// name and moved into place when finished; readers get a path to read. No other code spells a
// recording's file name. Thread-safe (the names are pure functions of the id).
class RecordingStore {
 public:
  virtual ~RecordingStore() = default;
  virtual std::string LivePath(const std::string& id) const = 0;      // written while the session is live
  virtual std::string FinishedPath(const std::string& id) const = 0;  // once finished
  // The file to read for a session in `state` ("live" reads the file being written).
  std::string PathFor(const std::string& id, const std::string& state) const {
    return state == "live" ? LivePath(id) : FinishedPath(id);
  }
  // PathFor's file name alone, as the session index shows it (SessionRow::recording).
  std::string NameFor(const std::string& id, const std::string& state) const {
    const std::string path = PathFor(id, state);
    return path.substr(path.find_last_of('/') + 1);
  }
  // Makes the first `bytes` bytes of the live file durable (they are in the file already: the
  // writer flushed them); `done(ok)` runs once they are (on any thread), and only then may the
  // session acknowledge the ticks they hold. Files in a directory are durable as written: done(true)
  // at once. An object store uploads the bytes not yet uploaded as the next segment, off the
  // caller's thread, and keeps them in the local file while it cannot. Called in order of bytes.
  virtual void Persist(const std::string& id, uint64_t bytes, std::function<void(bool ok)> done) {
    (void)id;
    (void)bytes;
    done(true);
  }
  // Brings the durable part of a live recording to LivePath(id) (another server taking the
  // session over: its owner's segments). False (with *error) when there is none.
  virtual bool Recover(const std::string& id, std::string* error) = 0;
  // The live file, closed, becomes the finished one. False with *error. An object store uploads
  // it off the caller's thread (Recorder::Finish has made every byte durable with Persist first).
  virtual bool Publish(const std::string& id, std::string* error) = 0;
  // Brings a finished recording to FinishedPath(id) before it is read: files in a directory are
  // there already (true; a missing one is the reader's error); an object store downloads it into
  // its cache (a recording another server made, or one its bounded cache let go). False with
  // *error when there is none. May throw StoreUnavailable; call it from a worker.
  virtual bool Fetch(const std::string& id, std::string* error) {
    (void)id;
    (void)error;
    return true;
  }
  virtual void Remove(const std::string& id) = 0;  // both files, whichever exist, and any copy in a store
  // Prometheus lines about the store itself (an object store's uploads); empty for files.
  virtual std::string MetricsText() const { return ""; }
};
// Recordings as files in `dir` (created): ID.live.mcap while live, ID.mcap once finished.
std::unique_ptr<RecordingStore> OpenRecordingDirectory(const std::string& dir, std::string* error);

// The data directory's stores: DIR/idms.db (SQLite, WAL), DIR/blobs/ and DIR/recordings/.
// Creates what is missing; removes stray temporary files and blobs no row names (what a crash
// can leave).
struct Storage {
  std::unique_ptr<BlobStore> blobs;
  std::unique_ptr<ModelStore> models;
  std::unique_ptr<SessionIndex> sessions;
  std::unique_ptr<RecordingStore> recordings;
};
// Object storage in place of DATA/blobs/ and DATA/recordings/ (--blobs, --recordings s3://...): a
// member left null stays in the data directory.
struct ObjectStores {
  std::unique_ptr<BlobStore> blobs;
  std::unique_ptr<RecordingStore> recordings;
};
// Blobs no row names are removed only from DATA/blobs/: a bucket may be shared by several servers.
bool OpenStorage(const std::string& data_dir, Storage* storage, std::string* error, ObjectStores objects = {});
// The same with the model library and the session index given (PostgreSQL's, with --store):
// only the blobs and recordings are opened under `data_dir` (unless given), and no idms.db is
// made. Blobs no row names are kept: another server sharing the database and the blobs may be
// between storing an upload's blob and committing its row.
bool OpenStorage(const std::string& data_dir, std::unique_ptr<ModelStore> models,
                 std::unique_ptr<SessionIndex> sessions, Storage* storage, std::string* error,
                 ObjectStores objects = {});

// The directory store alone (tests, tools).
std::unique_ptr<BlobStore> OpenBlobDirectory(const std::string& dir, std::string* error);
// The SQLite stores alone.
std::unique_ptr<ModelStore> OpenSqliteModelStore(const std::string& db_path, std::string* error);
std::unique_ptr<SessionIndex> OpenSqliteSessionIndex(const std::string& db_path, std::string* error);

// The current UTC time as ISO 8601 ("2026-11-23T19:04:05Z"), as the stores write it.
std::string UtcNow();
// The same with milliseconds ("2026-11-23T19:04:05.123Z"): a session's start, so that sessions
// started within one second are still listed newest first.
std::string UtcNowMs();

using ::idms::Sha256Hex;  // idms/protocol/digest.h: SHA-256 as 64 lowercase hex digits

}  // namespace idms::server
