// Connection slots: the total and per-address counts of open connections behind one mutex (a
// few nanoseconds per accept and close; an accept is microseconds).
#include "connection_slots.h"

#include <cstring>
#include <string_view>

#include "idms/sim/check.h"

namespace idms::server {

ConnectionSlot::ConnectionSlot(ConnectionSlot&& other) noexcept : owner_(other.owner_), key_(other.key_) {
  other.owner_ = nullptr;
}

ConnectionSlot& ConnectionSlot::operator=(ConnectionSlot&& other) noexcept {
  if (this != &other) {
    if (owner_ != nullptr) owner_->Release(key_);
    owner_ = other.owner_, key_ = other.key_;
    other.owner_ = nullptr;
  }
  return *this;
}

ConnectionSlot::~ConnectionSlot() {
  if (owner_ != nullptr) owner_->Release(key_);
}

size_t ConnectionSlots::KeyHash::operator()(const Key& k) const {
  return std::hash<std::string_view>()(std::string_view(reinterpret_cast<const char*>(k.data()), k.size()));
}

ConnectionSlots::Key ConnectionSlots::KeyOf(const boost::asio::ip::address& address) {
  Key key{};
  if (address.is_v4()) {
    // As an IPv4-mapped IPv6 address: ::ffff:a.b.c.d, the same key whichever socket family saw it.
    const auto v4 = address.to_v4().to_bytes();
    key[10] = key[11] = 0xff;
    std::memcpy(key.data() + 12, v4.data(), 4);
    return key;
  }
  const boost::asio::ip::address_v6 v6 = address.to_v6();
  if (v6.is_v4_mapped()) return KeyOf(boost::asio::ip::make_address_v4(boost::asio::ip::v4_mapped, v6));
  const auto bytes = v6.to_bytes();
  std::memcpy(key.data(), bytes.data(), 8);  // the /64
  return key;
}

ConnectionSlot ConnectionSlots::Acquire(const boost::asio::ip::address& address, Refusal* refusal) {
  const Key key = KeyOf(address);
  std::lock_guard lock(mu_);
  if (total_ >= max_total_) {
    *refusal = Refusal::kTotal;
    return {};
  }
  int& from = per_address_[key];
  if (max_per_address_ > 0 && from >= max_per_address_) {
    *refusal = Refusal::kAddress;
    return {};
  }
  ++from, ++total_;
  open_->store(total_, std::memory_order_relaxed);
  *refusal = Refusal::kNone;
  return ConnectionSlot(this, key);
}

void ConnectionSlots::Release(const Key& key) {
  std::lock_guard lock(mu_);
  const auto it = per_address_.find(key);
  IDMS_CHECK(it != per_address_.end() && it->second > 0 && total_ > 0);
  if (--it->second == 0) per_address_.erase(it);
  --total_;
  open_->store(total_, std::memory_order_relaxed);
}

int ConnectionSlots::open() const {
  std::lock_guard lock(mu_);
  return total_;
}

int ConnectionSlots::open_from(const boost::asio::ip::address& address) const {
  const Key key = KeyOf(address);
  std::lock_guard lock(mu_);
  const auto it = per_address_.find(key);
  return it == per_address_.end() ? 0 : it->second;
}

}  // namespace idms::server
