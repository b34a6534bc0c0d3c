// Recordings in an S3 bucket. A live recording is written to a local file (the cache directory)
// and Persist uploads what the writer has flushed since the last upload as the next segment,
// recordings/ID/GGGGGG-OOOOOOOOOOOOOOOOOOOO (G: the writer's generation, O: the segment's first
// byte), so that the segments of the newest generation, in order, are the durable prefix of the
// live file. Publish uploads the finished file as recordings/ID.mcap, then deletes the segments.
// Uploads run on the store's own threads, one at a time per recording, retried while the store
// is down; the bytes wait in the local file.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <filesystem>
#include <map>
#include <mutex>
#include <random>
#include <thread>

#include "idms/server/log.h"
#include "s3_stores.h"

namespace idms::server {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

constexpr const char* kPrefix = "recordings/";
constexpr uint32_t kMaxGeneration = 999999;

// An open file shared by whoever reads it (an upload in flight keeps it open after a rename).
struct File {
  explicit File(int f) : fd(f) {}
  ~File() {
    if (fd >= 0) ::close(fd);
  }
  File(const File&) = delete;
  File& operator=(const File&) = delete;
  int fd;
};

std::shared_ptr<const File> OpenForReading(const std::string& path, struct stat* st) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return nullptr;
  auto f = std::make_shared<const File>(fd);
  if (st != nullptr && ::fstat(fd, st) != 0) return nullptr;
  return f;
}

// Session ids are the server's own ("2026-11-28-0123456789ab"); anything else never becomes a key
// or a path.
bool IsSafeId(const std::string& id) {
  return !id.empty() && id.size() <= 128 && id.front() != '.' &&
         id.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_.-") == std::string::npos;
}

std::string Padded(uint64_t value, int width) {
  std::string s = std::to_string(value);
  return std::string(static_cast<size_t>(std::max(0, width - static_cast<int>(s.size()))), '0') + s;
}

std::string FinalKey(const std::string& id) { return kPrefix + id + ".mcap"; }
std::string SegmentPrefix(const std::string& id) { return kPrefix + id + "/"; }
std::string SegmentKey(const std::string& id, uint32_t generation, uint64_t offset) {
  return SegmentPrefix(id) + Padded(generation, 6) + "-" + Padded(offset, 20);
}

struct Segment {
  std::string key;
  uint32_t generation = 0;
  uint64_t offset = 0, size = 0;
};

// The listed segments of one recording, by generation and offset; keys that are not segments are
// ignored.
std::vector<Segment> ParseSegments(const std::string& id, const std::vector<S3Object>& objects) {
  std::vector<Segment> out;
  const std::string prefix = SegmentPrefix(id);
  for (const S3Object& o : objects) {
    const std::string name = o.key.substr(prefix.size());
    if (name.size() != 27 || name[6] != '-' || name.find_first_not_of("0123456789-") != std::string::npos) continue;
    Segment s{o.key, static_cast<uint32_t>(std::stoul(name.substr(0, 6))), std::stoull(name.substr(7)), o.size};
    out.push_back(s);
  }
  std::sort(out.begin(), out.end(), [](const Segment& a, const Segment& b) {
    return std::tie(a.generation, a.offset) < std::tie(b.generation, b.offset);
  });
  return out;
}

// The newest generation's segments from byte 0 on, up to the first gap: the durable prefix.
std::vector<Segment> DurablePrefix(const std::vector<Segment>& all) {
  std::vector<Segment> out;
  if (all.empty()) return out;
  const uint32_t newest = all.back().generation;
  uint64_t next = 0;
  for (const Segment& s : all) {
    if (s.generation != newest || s.offset != next) continue;
    out.push_back(s);
    next += s.size;
  }
  return out;
}

class S3RecordingStore final : public RecordingStore {
 public:
  S3RecordingStore(std::unique_ptr<S3Client> s3, std::string dir, S3RecordingOptions options)
      : s3_(std::move(s3)), dir_(std::move(dir)), options_(options) {
    for (int i = 0; i < std::max(1, options_.upload_threads); ++i) threads_.emplace_back([this] { Work(); });
  }

  ~S3RecordingStore() override {
    // What is queued gets a few seconds to reach the store (a SIGTERM with the store up loses
    // nothing); past that, or while it is down, the bytes stay in the local files.
    std::unique_lock lock(mu_);
    idle_.wait_for(lock, options_.drain_timeout,
                   [this] { return (ready_.empty() && busy_ == 0) || Clock::now() < down_until_; });
    stopping_ = true;
    lock.unlock();
    work_.notify_all();
    for (std::thread& t : threads_) t.join();
  }

  std::string LivePath(const std::string& id) const override { return dir_ + "/" + id + ".live.mcap"; }
  std::string FinishedPath(const std::string& id) const override { return dir_ + "/" + id + ".mcap"; }

  void Persist(const std::string& id, uint64_t bytes, std::function<void(bool ok)> done) override {
    std::vector<std::function<void(bool)>> refused;  // answered false, outside the lock
    bool durable = false;
    {
      std::lock_guard lock(mu_);
      struct stat st {};
      if (!IsSafeId(id) || ::stat(LivePath(id).c_str(), &st) != 0) {
        Log(LogLevel::kError, "recording not persisted: no live file", {{"session", id}, {"path", LivePath(id)}});
        refused.push_back(std::move(done));
      } else {
        Entry& e = entries_[id];
        e.last_used = Clock::now();
        // A live file the store has not seen (a new writer, after a takeover or a resume)
        // starts a new generation from byte 0.
        if (!e.live.file || e.live.ino != st.st_ino || e.live.dev != st.st_dev) {
          refused.push_back(std::move(e.live.done));
          NewIncarnation(&e, id);
        }
        if (!e.live.file) {
          Log(LogLevel::kError, "recording not persisted: cannot open the live file",
              {{"session", id}, {"error", std::strerror(errno)}});
          refused.push_back(std::move(done));
        } else if (bytes <= e.live.uploaded) {
          durable = true;
        } else {
          // Only the newest request waits: acknowledgements are cumulative, so an older one
          // answered false costs the agent nothing (the newer one covers its ticks).
          e.live.wanted = std::max(e.live.wanted, bytes);
          refused.push_back(std::move(e.live.done));
          e.live.done = std::move(done);
          e.live.done_bytes = bytes;
          Enqueue(id, &e);
        }
      }
    }
    for (auto& f : refused) {
      if (f) f(false);
    }
    if (durable && done) done(true);
  }

  bool Recover(const std::string& id, std::string* error) override {
    if (!IsSafeId(id)) {
      *error = "not a session id: " + id;
      return false;
    }
    // What this server knew of the session's live file is out of date (another owner since).
    std::function<void(bool)> dropped;
    {
      std::lock_guard lock(mu_);
      if (auto it = entries_.find(id); it != entries_.end()) {
        dropped = std::move(it->second.live.done);
        it->second.live = Live();
        ++it->second.incarnation;
      }
    }
    if (dropped) dropped(false);
    std::vector<S3Object> objects;
    if (s3_->List(SegmentPrefix(id), &objects, error) != S3Result::kOk) return false;
    const std::vector<Segment> all = ParseSegments(id, objects);
    const std::vector<Segment> durable = DurablePrefix(all);
    uint64_t durable_bytes = 0;
    for (const Segment& s : durable) durable_bytes += s.size;
    {
      std::lock_guard lock(mu_);
      if (!all.empty()) entries_[id].recovered_generation = all.back().generation;
    }
    // A local file at least as long (this server restarted under the session) holds more.
    std::error_code ec;
    const bool local = fs::exists(LivePath(id), ec);
    if (local && fs::file_size(LivePath(id), ec) >= durable_bytes) return true;
    if (durable.empty()) {
      *error = "no durable recording of session " + id + " in " + s3_->location().Describe();
      return false;
    }
    return Download(durable, LivePath(id), error);
  }

  bool Publish(const std::string& id, std::string* error) override {
    std::error_code ec;
    fs::rename(LivePath(id), FinishedPath(id), ec);
    if (ec) {
      *error = "rename " + LivePath(id) + " -> " + FinishedPath(id) + ": " + ec.message();
      return false;
    }
    struct stat st {};
    std::shared_ptr<const File> file = OpenForReading(FinishedPath(id), &st);
    if (!file) {
      *error = "cannot open " + FinishedPath(id) + ": " + std::strerror(errno);
      return false;
    }
    std::function<void(bool)> dropped;
    {
      std::lock_guard lock(mu_);
      Entry& e = entries_[id];
      // The segments this file replaces: its own generation's and every older one (all of them
      // when it never uploaded one and found none to recover: a repair after a crash).
      e.final_generation = e.live.generation != 0        ? e.live.generation
                           : e.recovered_generation != 0 ? e.recovered_generation
                                                         : kMaxGeneration;
      e.last_used = Clock::now();
      dropped = std::move(e.live.done);
      e.live = Live();
      ++e.incarnation;
      e.final_file = std::move(file);
      e.final_bytes = static_cast<uint64_t>(st.st_size);
      Enqueue(id, &e);
    }
    if (dropped) dropped(false);
    return true;
  }

  bool Fetch(const std::string& id, std::string* error) override {
    if (!IsSafeId(id)) {
      *error = "not a session id: " + id;
      return false;
    }
    std::error_code ec;
    if (fs::exists(FinishedPath(id), ec)) {
      fs::last_write_time(FinishedPath(id), fs::file_time_type::clock::now(), ec);  // recently used
      return true;
    }
    // The finished object; until its upload is done (or if it failed), the segments, which hold
    // the whole closed file (Finish made it durable before publishing).
    const std::string tmp = dir_ + "/" + id + ".mcap.fetch-" + std::to_string(Random());
    // The temporary file goes whatever happens (a refusal, the store going down mid-way).
    struct Remover {
      const std::string& path;
      ~Remover() {
        std::error_code ignored;
        fs::remove(path, ignored);
      }
    } remover{tmp};
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) {
      *error = "cannot create " + tmp + ": " + std::strerror(errno);
      return false;
    }
    uint64_t size = 0;
    S3Result r = S3Result::kRefused;
    try {
      r = s3_->GetToFile(FinalKey(id), fd, &size, error);
    } catch (...) {
      ::close(fd);
      throw;
    }
    ::close(fd);
    bool ok = r == S3Result::kOk;
    if (r == S3Result::kNotFound) {
      std::vector<S3Object> objects;
      if (s3_->List(SegmentPrefix(id), &objects, error) == S3Result::kOk) {
        const std::vector<Segment> durable = DurablePrefix(ParseSegments(id, objects));
        if (durable.empty()) {
          *error = "no recording of session " + id + " in " + s3_->location().Describe();
        } else {
          ok = Download(durable, tmp, error);
        }
      }
    }
    if (!ok) return false;
    fs::rename(tmp, FinishedPath(id), ec);
    if (ec) {
      *error = "rename " + tmp + " -> " + FinishedPath(id) + ": " + ec.message();
      return false;
    }
    TrimCache();
    return true;
  }

  std::string MetricsText() const override {
    std::lock_guard lock(mu_);
    uint64_t pending = 0;
    for (const auto& [id, e] : entries_) pending += e.live.wanted - std::min(e.live.wanted, e.live.uploaded);
    const bool available = !down_logged_;
    const auto line = [](const char* name, const char* type, const char* help, uint64_t value) {
      return std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " " + type + "\n" + name + " " +
             std::to_string(value) + "\n";
    };
    return line("idms_recording_segments_total", "counter", "Recording segments uploaded to the object store.",
                segments_) +
           line("idms_recording_segment_bytes_total", "counter", "Bytes uploaded as recording segments.",
                segment_bytes_) +
           line("idms_recording_published_total", "counter", "Finished recordings uploaded whole.", published_) +
           line("idms_recording_pending_bytes", "gauge",
                "Bytes of live recordings flushed but not yet in the object store (acknowledgements wait for them).",
                pending) +
           line("idms_object_store_available", "gauge",
                "Whether the object store took the last recording upload (0: down, uploads retried).", available);
  }

  void Remove(const std::string& id) override {
    if (!IsSafeId(id)) return;
    {
      std::lock_guard lock(mu_);
      if (auto it = entries_.find(id); it != entries_.end()) {
        it->second.live = Live();
        it->second.final_file.reset();
        ++it->second.incarnation;
      }
    }
    std::error_code ec;
    fs::remove(LivePath(id), ec);
    fs::remove(FinishedPath(id), ec);
    // The store's copies (throws StoreUnavailable while it is down: the delete is answered 503).
    std::string error;
    std::vector<S3Object> objects;
    s3_->Delete(FinalKey(id), &error);
    if (s3_->List(SegmentPrefix(id), &objects, &error) == S3Result::kOk) {
      for (const S3Object& o : objects) s3_->Delete(o.key, &error);
    }
  }

 private:
  // The live file of the current writer and how much of it is in the store.
  struct Live {
    std::shared_ptr<const File> file;
    dev_t dev = 0;
    ino_t ino = 0;
    uint32_t generation = 0;  // 0: not chosen yet (the first upload lists the older ones)
    uint64_t uploaded = 0;    // bytes [0, uploaded) are in segments
    uint64_t wanted = 0;      // bytes [0, wanted) must be
    std::function<void(bool)> done;
    uint64_t done_bytes = 0;
  };
  struct Entry {
    Live live;
    uint64_t incarnation = 0;           // bumped whenever `live` is replaced: results of older jobs are dropped
    uint32_t recovered_generation = 0;  // the newest generation Recover found
    // Finished, waiting for its upload as recordings/ID.mcap; then the segments of generations up
    // to final_generation go.
    std::shared_ptr<const File> final_file;
    uint64_t final_bytes = 0;
    uint32_t final_generation = 0;
    bool queued = false, busy = false;
    Clock::time_point last_used{};  // the last Persist or Publish: an entry idle for long is dropped
    Clock::time_point retry_at{};
    milliseconds backoff{0};
  };

  void NewIncarnation(Entry* e, const std::string& id) {
    e->live = Live();
    ++e->incarnation;
    struct stat st {};
    e->live.file = OpenForReading(LivePath(id), &st);
    e->live.dev = st.st_dev;
    e->live.ino = st.st_ino;
  }

  static bool HasWork(const Entry& e) { return e.final_file || e.live.wanted > e.live.uploaded; }

  // Entries with nothing to do: dropped once published, or when no Persist came for ten minutes
  // (a session given up to another server, or gone): their files close. Under mu_.
  void Sweep(Clock::time_point now) {
    for (auto it = entries_.begin(); it != entries_.end();) {
      const Entry& e = it->second;
      const bool idle = !e.busy && !e.queued && !HasWork(e) && !e.live.done;
      if (idle && (!e.live.file || now - e.last_used > std::chrono::minutes(10))) {
        it = entries_.erase(it);
      } else {
        ++it;
      }
    }
  }

  void Enqueue(const std::string& id, Entry* e) {
    if (e->queued || e->busy) return;
    e->queued = true;
    ready_.push_back(id);
    work_.notify_one();
  }

  // The uploaders: each takes a recording whose turn it is and does its next job.
  void Work() {
    std::unique_lock lock(mu_);
    while (!stopping_) {
      const Clock::time_point now = Clock::now();
      Clock::time_point wake = Clock::time_point::max();
      std::string id;
      if (now < down_until_) {
        wake = down_until_;
      } else {
        for (auto it = ready_.begin(); it != ready_.end(); ++it) {
          const Entry& e = entries_[*it];
          if (e.retry_at > now) {
            wake = std::min(wake, e.retry_at);
            continue;
          }
          id = *it;
          ready_.erase(it);
          break;
        }
      }
      if (id.empty()) {
        if (wake == Clock::time_point::max()) {
          work_.wait(lock);
        } else {
          work_.wait_until(lock, wake);
        }
        continue;
      }
      Entry& e = entries_[id];
      e.queued = false;
      e.busy = true;
      ++busy_;
      std::vector<std::function<void(bool)>> answers;
      RunJob(id, e, lock, &answers);
      e.busy = false;
      --busy_;
      if (HasWork(e)) Enqueue(id, &e);
      Sweep(now);
      if (ready_.empty() && busy_ == 0) idle_.notify_all();
      // Acknowledgements run outside the lock, in order.
      lock.unlock();
      for (auto& a : answers) a(true);
      lock.lock();
    }
  }

  // One job of one recording, with the lock released around the store's round trips.
  void RunJob(const std::string& id, Entry& e, std::unique_lock<std::mutex>& lock,
              std::vector<std::function<void(bool)>>* answers) {
    const uint64_t incarnation = e.incarnation;
    std::string error;
    bool unavailable = false, refused = false;
    if (e.final_file) {
      // The finished file as one object, then the segments it replaces.
      const std::shared_ptr<const File> file = e.final_file;
      const uint64_t bytes = e.final_bytes;
      const uint32_t generation = e.final_generation;
      lock.unlock();
      try {
        refused = s3_->PutFile(FinalKey(id), file->fd, 0, bytes, &error) != S3Result::kOk;
        if (!refused) DeleteSegments(id, [generation](const Segment& s) { return s.generation <= generation; });
      } catch (const StoreUnavailable& ex) {
        unavailable = true;
        error = ex.what();
      }
      lock.lock();
      if (!unavailable && !refused && e.incarnation == incarnation && e.final_file == file) {
        e.final_file.reset();
        ++published_;
        lock.unlock();
        TrimCache();
        lock.lock();
      }
    } else if (e.live.wanted > e.live.uploaded) {
      // The bytes flushed since the last segment, as the next segment.
      const std::shared_ptr<const File> file = e.live.file;
      uint32_t generation = e.live.generation;
      const uint64_t first = e.live.uploaded, last = e.live.wanted;
      lock.unlock();
      uint32_t older = 0;
      try {
        if (generation == 0) {
          // A new writer: the generation after every one in the store.
          std::vector<S3Object> objects;
          refused = s3_->List(SegmentPrefix(id), &objects, &error) != S3Result::kOk;
          const std::vector<Segment> all = ParseSegments(id, objects);
          older = all.empty() ? 0 : all.back().generation;
          generation = std::min(older + 1, kMaxGeneration);
        }
        if (!refused) {
          refused =
              s3_->PutFile(SegmentKey(id, generation, first), file->fd, first, last - first, &error) != S3Result::kOk;
        }
        // The first segment of a new generation holds everything the older ones did (the new
        // writer copied the recovered or finished recording first): they go.
        if (!refused && older > 0 && first == 0) {
          DeleteSegments(id, [generation](const Segment& s) { return s.generation < generation; });
        }
      } catch (const StoreUnavailable& ex) {
        unavailable = true;
        error = ex.what();
      }
      lock.lock();
      if (!unavailable && !refused && e.incarnation == incarnation) {
        e.live.generation = generation;
        e.live.uploaded = std::max(e.live.uploaded, last);
        ++segments_;
        segment_bytes_ += last - first;
        if (e.live.done && e.live.done_bytes <= e.live.uploaded) {
          answers->push_back(std::move(e.live.done));
          e.live.done = nullptr;
        }
      }
    }
    // Down: everyone waits (a refused connection costs microseconds, so retries are cheap and
    // quick); refused: this recording waits longer each time.
    const Clock::time_point now = Clock::now();
    if (unavailable) {
      down_backoff_ = std::min(options_.max_retry, std::max(milliseconds(100), down_backoff_ * 2));
      down_until_ = now + down_backoff_;
      if (!std::exchange(down_logged_, true)) {
        Log(LogLevel::kWarn, "object store unavailable: recordings wait in their local files", {{"error", error}});
      }
    } else if (refused) {
      e.backoff = std::min(milliseconds(30000), std::max(milliseconds(1000), e.backoff * 2));
      e.retry_at = now + e.backoff;
      Log(LogLevel::kError, "recording upload refused; retrying",
          {{"session", id}, {"error", error}, {"retry_ms", e.backoff.count()}});
    } else {
      e.backoff = milliseconds(0);
      down_backoff_ = milliseconds(0);
      if (std::exchange(down_logged_, false)) Log(LogLevel::kInfo, "object store available again");
    }
  }

  template <class Predicate>
  void DeleteSegments(const std::string& id, Predicate which) {
    std::vector<S3Object> objects;
    std::string error;
    if (s3_->List(SegmentPrefix(id), &objects, &error) != S3Result::kOk) return;
    for (const Segment& s : ParseSegments(id, objects)) {
      if (which(s)) s3_->Delete(s.key, &error);
    }
  }

  // The segments, in order, into `path` (created or truncated).
  bool Download(const std::vector<Segment>& segments, const std::string& path, std::string* error) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) {
      *error = "cannot create " + path + ": " + std::strerror(errno);
      return false;
    }
    bool ok = true;
    try {
      for (const Segment& s : segments) {
        uint64_t size = 0;
        if (s3_->GetToFile(s.key, fd, &size, error) != S3Result::kOk || size != s.size) {
          if (error->empty())
            *error = s.key + ": " + std::to_string(size) + " bytes, listed as " + std::to_string(s.size);
          ok = false;
          break;
        }
      }
    } catch (...) {
      ::close(fd);
      throw;
    }
    ok = ::fsync(fd) == 0 && ok;
    ::close(fd);
    return ok;
  }

  // Finished recordings in the cache beyond its bound go, least recently used first; never one
  // still waiting for its upload, nor one used in the last minute (a reader may be opening it).
  void TrimCache() {
    std::vector<std::pair<fs::file_time_type, fs::path>> finished;
    uint64_t total = 0;
    std::error_code ec;
    for (const fs::directory_entry& d : fs::directory_iterator(dir_, ec)) {
      const std::string name = d.path().filename().string();
      if (name.size() < 6 || name.substr(name.size() - 5) != ".mcap" || name.find(".live.") != std::string::npos)
        continue;
      total += d.file_size(ec);
      finished.emplace_back(d.last_write_time(ec), d.path());
    }
    if (total <= options_.cache_bytes) return;
    std::sort(finished.begin(), finished.end());
    const auto recent = fs::file_time_type::clock::now() - std::chrono::minutes(1);
    for (const auto& [when, path] : finished) {
      if (total <= options_.cache_bytes || when > recent) break;
      const std::string id = path.filename().string().substr(0, path.filename().string().size() - 5);
      {
        std::lock_guard lock(mu_);
        if (auto it = entries_.find(id); it != entries_.end() && it->second.final_file) continue;
      }
      const uint64_t size = fs::file_size(path, ec);
      if (fs::remove(path, ec)) total -= size;
    }
  }

  static uint64_t Random() {
    thread_local std::mt19937_64 rng{std::random_device{}()};
    return rng();
  }

  std::unique_ptr<S3Client> s3_;
  std::string dir_;
  S3RecordingOptions options_;
  mutable std::mutex mu_;
  std::condition_variable work_, idle_;
  std::map<std::string, Entry> entries_;  // under mu_
  std::deque<std::string> ready_;         // recordings with a job, each once
  int busy_ = 0;
  bool stopping_ = false;
  Clock::time_point down_until_{};
  milliseconds down_backoff_{0};
  bool down_logged_ = false;
  uint64_t segments_ = 0, segment_bytes_ = 0, published_ = 0;
  std::vector<std::thread> threads_;  // last: they stop before the rest goes
};

}  // namespace

std::unique_ptr<RecordingStore> OpenS3RecordingStore(const S3Location& location, const S3Credentials& credentials,
                                                     const std::string& cache_dir, std::string* error,
                                                     S3RecordingOptions options) {
  std::error_code ec;
  fs::create_directories(cache_dir, ec);
  if (ec) {
    *error = "cannot create " + cache_dir + ": " + ec.message();
    return nullptr;
  }
  auto s3 = std::make_unique<S3Client>(location, credentials);
  try {
    if (s3->CheckBucket(error) != S3Result::kOk) return nullptr;
  } catch (const StoreUnavailable& e) {
    *error = e.what();
    return nullptr;
  }
  // What a crash left while fetching a finished recording.
  for (const fs::directory_entry& d : fs::directory_iterator(cache_dir, ec)) {
    if (d.path().filename().string().find(".mcap.fetch-") != std::string::npos) fs::remove(d.path(), ec);
  }
  return std::make_unique<S3RecordingStore>(std::move(s3), cache_dir, options);
}

}  // namespace idms::server
