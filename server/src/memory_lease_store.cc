// Session ownership leases in this process (one server, no database): LeaseStore's rules by the
// steady clock, so that code written against leases runs the same on one machine and on several.
#include <map>
#include <mutex>

#include "idms/server/storage.h"

namespace idms::server {
namespace {

class MemoryLeaseStore final : public LeaseStore {
 public:
  std::optional<int64_t> Acquire(const std::string& session_id, const std::string& node_id,
                                 std::chrono::milliseconds ttl) override {
    const auto now = Clock::now();
    std::lock_guard lock(mu_);
    Entry& e = leases_[session_id];  // a new session's entry has epoch 0 and has expired
    if (e.expires > now && e.holder != node_id) return std::nullopt;
    e.holder = node_id;
    e.epoch += 1;
    e.expires = now + ttl;
    return e.epoch;
  }

  bool Renew(const std::string& session_id, const std::string& node_id, int64_t epoch,
             std::chrono::milliseconds ttl) override {
    const auto now = Clock::now();
    std::lock_guard lock(mu_);
    const auto it = leases_.find(session_id);
    if (it == leases_.end() || !Holds(it->second, node_id, epoch, now)) return false;
    it->second.expires = now + ttl;
    return true;
  }

  void Release(const std::string& session_id, const std::string& node_id, int64_t epoch) override {
    std::lock_guard lock(mu_);
    const auto it = leases_.find(session_id);
    if (it != leases_.end() && Holds(it->second, node_id, epoch, Clock::now())) it->second.expires = {};
  }

  std::optional<Lease> Holder(const std::string& session_id) override {
    const auto now = Clock::now();
    std::lock_guard lock(mu_);
    const auto it = leases_.find(session_id);
    if (it == leases_.end() || it->second.expires <= now) return std::nullopt;
    const Entry& e = it->second;
    return Lease{e.holder, e.epoch, std::chrono::duration_cast<std::chrono::milliseconds>(e.expires - now)};
  }

 private:
  using Clock = std::chrono::steady_clock;
  struct Entry {
    std::string holder;
    int64_t epoch = 0;
    Clock::time_point expires{};
  };
  static bool Holds(const Entry& e, const std::string& node_id, int64_t epoch, Clock::time_point now) {
    return e.holder == node_id && e.epoch == epoch && e.expires > now;
  }

  std::mutex mu_;
  std::map<std::string, Entry> leases_;  // entries stay after release: epochs are never reused
};

}  // namespace

std::unique_ptr<LeaseStore> MakeMemoryLeaseStore() { return std::make_unique<MemoryLeaseStore>(); }

}  // namespace idms::server
