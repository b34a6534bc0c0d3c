// Open connections counted in one place, in total and per client address: a slot is taken when a
// connection is accepted and moves with it (HTTP session, then WebSocket session), so every kind of
// connection counts against the limits until it closes.
#pragma once

#include <array>
#include <atomic>
#include <boost/asio/ip/address.hpp>
#include <cstdint>
#include <mutex>
#include <unordered_map>

namespace idms::server {

class ConnectionSlots;

// One open connection's place. Move-only; released when destroyed (or when moved from, never).
class ConnectionSlot {
 public:
  ConnectionSlot() = default;
  ConnectionSlot(ConnectionSlot&& other) noexcept;
  ConnectionSlot& operator=(ConnectionSlot&& other) noexcept;
  ConnectionSlot(const ConnectionSlot&) = delete;
  ConnectionSlot& operator=(const ConnectionSlot&) = delete;
  ~ConnectionSlot();
  explicit operator bool() const { return owner_ != nullptr; }

 private:
  friend class ConnectionSlots;
  using Key = std::array<uint8_t, 16>;
  ConnectionSlot(ConnectionSlots* owner, Key key) : owner_(owner), key_(key) {}
  ConnectionSlots* owner_ = nullptr;
  Key key_{};
};

class ConnectionSlots {
 public:
  enum class Refusal { kNone, kTotal, kAddress };

  // max_per_address 0: no per-address limit. `open` is the gauge kept equal to the slots held.
  ConnectionSlots(int max_total, int max_per_address, std::atomic<int64_t>* open)
      : max_total_(max_total), max_per_address_(max_per_address), open_(open) {}

  // A slot for a client at `address`, or an empty one and *refusal saying which limit is full.
  // Any thread. IPv4-mapped IPv6 addresses count as their IPv4 address; other IPv6 addresses by
  // their /64, which one host usually holds whole (a per-address limit would not bind it).
  ConnectionSlot Acquire(const boost::asio::ip::address& address, Refusal* refusal);

  int open() const;
  int open_from(const boost::asio::ip::address& address) const;

 private:
  friend class ConnectionSlot;
  using Key = ConnectionSlot::Key;
  struct KeyHash {
    size_t operator()(const Key& k) const;
  };
  static Key KeyOf(const boost::asio::ip::address& address);
  void Release(const Key& key);

  const int max_total_, max_per_address_;
  std::atomic<int64_t>* open_;
  mutable std::mutex mu_;
  int total_ = 0;
  std::unordered_map<Key, int, KeyHash> per_address_;  // only addresses with open connections
};

}  // namespace idms::server
