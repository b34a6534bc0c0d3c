// A live session's recording, written on the recorder thread (never on a network thread), and the
// copy of a recording into a writer (a resume after a restart; the repair after a crash).
#pragma once

#include <atomic>
#include <boost/asio/strand.hpp>
#include <boost/asio/thread_pool.hpp>
#include <functional>
#include <memory>
#include <string>

#include "idms/protocol/recording.h"
#include "idms/server/storage.h"
#include "session_summary.h"

namespace idms::server {

// What CopyRecording read: the device samples, the last tick, and their summary (its first and
// last sample times among its figures).
struct CopyStats {
  int64_t samples = 0;
  bool any_tick = false;
  uint64_t last_tick = 0;
  SessionSummary summary;
};
// Reads every message of a recording (finished, or unfinished after a crash: the reader recovers
// by a scan) into `writer` (null: only counts). False with *error on unreadable data.
bool CopyRecording(const std::string& path, RecordingWriter* writer, CopyStats* stats, std::string* error);

// What a session's recording starts with: nothing (a new session), the finished recording (a
// resume after a restart or the resume window), or the live recording another server left (a
// takeover: RecordingStore::Recover brought it here).
enum class RecordingStart { kNew, kContinueFinished, kContinueLive };

// The recording of one session. Every call posts to the recorder's strand and returns at once;
// the writer, its file and its buffers belong to that strand alone.
class Recorder : public std::enable_shared_from_this<Recorder> {
 public:
  // `bytes` and `failures` are the hub's counters for /metrics; `store` outlives the recorder.
  Recorder(boost::asio::thread_pool& pool, RecordingStore& store, std::string id, std::atomic<uint64_t>* bytes,
           std::atomic<uint64_t>* failures);

  // Opens the live file, and first copies into it what `from` says.
  void Start(RecordingWriterOptions options, RecordingStart from);
  // Closes the file without publishing it: another server owns the session now (its recording
  // continues there); the file stays under its live name.
  void Abandon();
  void Write(std::shared_ptr<const v1::Envelope> envelope, uint64_t log_ns, uint64_t publish_ns);
  // Closes the open chunk, so that everything written so far is in the file, and has the store
  // make it durable (RecordingStore::Persist); `done(ok)` then runs on the recorder's strand or
  // the store's thread (ok: durable, and the recording is healthy).
  void Flush(std::function<void(bool ok)> done = nullptr);
  // Closes the file (summary, indexes), has the store make all of it durable (Persist) and
  // publishes it; `done(ok)` runs on the recorder's strand once it is (it waits while an object
  // store is down).
  void Finish(std::function<void(bool ok)> done = nullptr);

 private:
  void Failed(const std::string& error);
  void CountBytes();

  boost::asio::strand<boost::asio::thread_pool::executor_type> strand_;
  RecordingStore& store_;
  std::string id_;
  RecordingWriter writer_;
  bool open_ = false;
  bool failed_ = false;
  std::atomic<uint64_t>* bytes_counter_;
  std::atomic<uint64_t>* failures_counter_;
  uint64_t bytes_counted_ = 0;
};

}  // namespace idms::server
