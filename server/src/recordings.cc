// A live session's recording on the recorder thread, and recordings copied into a writer.
#include "recordings.h"

#include <algorithm>
#include <boost/asio/post.hpp>
#include <filesystem>

#include "idms/server/log.h"
#include "server_internal.h"

namespace idms::server {

namespace asio = boost::asio;
namespace fs = std::filesystem;

bool CopyRecording(const std::string& path, RecordingWriter* writer, CopyStats* stats, std::string* error) {
  RecordingReader reader;
  if (!reader.Open(path, RecordingReaderOptions{}, error)) return false;
  RecordedMessage m;
  while (reader.Next(&m, error)) {
    if (m.envelope.has_device_samples()) {
      const v1::DeviceSamples& ds = m.envelope.device_samples();
      if (ds.samples_size() > 0) {
        stats->samples += ds.samples_size();
        stats->any_tick = true;
        stats->last_tick = ds.samples(ds.samples_size() - 1).tick();
      }
      stats->summary.Add(ds);
    }
    if (m.envelope.has_annotation())
      stats->summary.notes = std::max(stats->summary.notes, m.envelope.annotation().id());
    if (writer != nullptr && !writer->Write(m.envelope, m.log_time_ns, m.publish_time_ns, error)) return false;
  }
  return error->empty();
}

Recorder::Recorder(asio::thread_pool& pool, RecordingStore& store, std::string id, std::atomic<uint64_t>* bytes,
                   std::atomic<uint64_t>* failures)
    : strand_(asio::make_strand(pool)),
      store_(store),
      id_(std::move(id)),
      bytes_counter_(bytes),
      failures_counter_(failures) {}

void Recorder::Start(RecordingWriterOptions options, RecordingStart from) {
  asio::post(strand_, [self = shared_from_this(), options = std::move(options), from] {
    std::string error;
    const std::string live = self->store_.LivePath(self->id_);
    // A takeover's recovered live file is read from beside the new one.
    std::string source = from == RecordingStart::kContinueFinished ? self->store_.FinishedPath(self->id_) : "";
    if (from == RecordingStart::kContinueLive) {
      source = live + ".taken";
      std::error_code ec;
      fs::rename(live, source, ec);
      if (ec) source.clear();  // nothing was recovered: the recording starts again
    }
    if (!self->writer_.Open(live, options, &error)) return self->Failed(error);
    self->open_ = true;
    if (!source.empty() && fs::exists(source)) {
      CopyStats stats;
      if (!CopyRecording(source, &self->writer_, &stats, &error)) return self->Failed(error);
      std::error_code ec;
      if (from == RecordingStart::kContinueLive) fs::remove(source, ec);
    }
  });
}

void Recorder::Abandon() {
  asio::post(strand_, [self = shared_from_this()] {
    if (!self->open_) return;
    self->open_ = false;
    std::string error;
    self->writer_.Close(&error);
    self->CountBytes();
  });
}

void Recorder::Write(std::shared_ptr<const v1::Envelope> envelope, uint64_t log_ns, uint64_t publish_ns) {
  asio::post(strand_, [self = shared_from_this(), envelope = std::move(envelope), log_ns, publish_ns] {
    std::string error;
    if (self->open_ && !self->writer_.Write(*envelope, log_ns, publish_ns, &error)) self->Failed(error);
    self->CountBytes();
  });
}

void Recorder::Flush(std::function<void(bool)> done) {
  asio::post(strand_, [self = shared_from_this(), done = std::move(done)] {
    std::string error;
    // The open chunk too: the session acknowledges to its agent what this flush stored.
    if (self->open_ && !self->writer_.CloseChunk(&error)) self->Failed(error);
    self->CountBytes();
    if (!done) return;
    if (!self->open_ || self->failed_) return done(false);
    // Durable before acknowledged: the store may upload it first (off this strand).
    self->store_.Persist(self->id_, self->writer_.mcap().bytes_written(), std::move(done));
  });
}

void Recorder::Finish(std::function<void(bool)> done) {
  asio::post(strand_, [self = shared_from_this(), done = std::move(done)]() mutable {
    std::string error;
    if (!self->open_) {
      if (done) done(false);
      return;
    }
    self->open_ = false;
    if (!self->writer_.Close(&error)) {
      self->Failed(error);
      self->CountBytes();
      if (done) done(false);
      return;
    }
    self->CountBytes();
    // Every byte of the closed file durable (an object store uploads its last segment), then
    // published: the agent's final acknowledgement follows `done`.
    self->store_.Persist(self->id_, self->writer_.mcap().bytes_written(),
                         [self, done = std::move(done)](bool durable) mutable {
                           asio::post(self->strand_, [self, done = std::move(done), durable] {
                             std::string publish_error;
                             bool ok = false;
                             if (!durable) {
                               self->Failed("the finished recording could not be made durable");
                             } else if (!self->store_.Publish(self->id_, &publish_error)) {
                               // The finished file stays under its live name; the next start-up
                               // repairs and indexes it.
                               self->Failed(publish_error);
                             } else {
                               ok = !self->failed_;
                             }
                             if (done) done(ok);
                           });
                         });
  });
}

void Recorder::Failed(const std::string& error) {
  open_ = false;
  failed_ = true;
  ++*failures_counter_;
  Log(LogLevel::kError, "recording failed", {{"session", id_}, {"error", error}});
}

void Recorder::CountBytes() {
  const uint64_t now = writer_.mcap().bytes_written();
  if (now > bytes_counted_) *bytes_counter_ += now - bytes_counted_;
  bytes_counted_ = now;
}

}  // namespace idms::server
