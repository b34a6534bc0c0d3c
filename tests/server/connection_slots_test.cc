// Connection slots: the total and per-address limits, release on destruction (once, whichever
// object holds the slot after moves), the gauge, and which addresses count as one client.
#include "../../server/src/connection_slots.h"

#include <gtest/gtest.h>

#include <optional>
#include <vector>

namespace idms::server {
namespace {

using boost::asio::ip::make_address;
using Refusal = ConnectionSlots::Refusal;

TEST(ConnectionSlots, TotalAndPerAddressLimitsAndTheGauge) {
  std::atomic<int64_t> gauge{0};
  ConnectionSlots slots(3, 2, &gauge);
  Refusal refusal;
  const auto a = make_address("10.0.0.1"), b = make_address("10.0.0.2"), c = make_address("10.0.0.3");
  std::vector<ConnectionSlot> held;
  held.push_back(slots.Acquire(a, &refusal));
  held.push_back(slots.Acquire(a, &refusal));
  EXPECT_TRUE(held[0] && held[1]);
  EXPECT_FALSE(slots.Acquire(a, &refusal));
  EXPECT_EQ(refusal, Refusal::kAddress);
  held.push_back(slots.Acquire(b, &refusal));
  EXPECT_TRUE(held.back());
  EXPECT_EQ(refusal, Refusal::kNone);
  EXPECT_FALSE(slots.Acquire(c, &refusal));
  EXPECT_EQ(refusal, Refusal::kTotal);
  EXPECT_EQ(gauge.load(), 3);
  EXPECT_EQ(slots.open_from(a), 2);
  // A refusal takes nothing; a released slot is free again.
  held.erase(held.begin());
  EXPECT_EQ(gauge.load(), 2);
  EXPECT_EQ(slots.open_from(a), 1);
  EXPECT_TRUE(slots.Acquire(c, &refusal));  // taken and released at once
  held.clear();
  EXPECT_EQ(gauge.load(), 0);
  EXPECT_EQ(slots.open(), 0);
  EXPECT_EQ(slots.open_from(a), 0);
}

TEST(ConnectionSlots, AMovedSlotIsReleasedOnceByItsLastHolder) {
  std::atomic<int64_t> gauge{0};
  ConnectionSlots slots(10, 10, &gauge);
  Refusal refusal;
  std::optional<ConnectionSlot> http(slots.Acquire(make_address("127.0.0.1"), &refusal));
  ConnectionSlot websocket = std::move(*http);  // as at an upgrade
  http.reset();
  EXPECT_EQ(gauge.load(), 1);
  ConnectionSlot other = slots.Acquire(make_address("127.0.0.1"), &refusal);
  other = std::move(websocket);  // releases other's own slot, takes websocket's
  EXPECT_EQ(gauge.load(), 1);
  other = ConnectionSlot();
  EXPECT_EQ(gauge.load(), 0);
}

TEST(ConnectionSlots, IPv6CountsByItsSlash64AndMappedIPv4AsIPv4) {
  std::atomic<int64_t> gauge{0};
  ConnectionSlots slots(100, 1, &gauge);
  Refusal refusal;
  const ConnectionSlot v6 = slots.Acquire(make_address("2001:db8::1"), &refusal);
  EXPECT_TRUE(v6);
  EXPECT_FALSE(slots.Acquire(make_address("2001:db8::2:3:4:5"), &refusal));  // same /64
  EXPECT_EQ(refusal, Refusal::kAddress);
  EXPECT_TRUE(slots.Acquire(make_address("2001:db8:0:1::1"), &refusal));  // the next /64
  const ConnectionSlot v4 = slots.Acquire(make_address("192.0.2.7"), &refusal);
  EXPECT_TRUE(v4);
  EXPECT_FALSE(slots.Acquire(make_address("::ffff:192.0.2.7"), &refusal));
  EXPECT_TRUE(slots.Acquire(make_address("192.0.2.8"), &refusal));
}

TEST(ConnectionSlots, ZeroMeansNoPerAddressLimit) {
  std::atomic<int64_t> gauge{0};
  ConnectionSlots slots(5, 0, &gauge);
  Refusal refusal;
  std::vector<ConnectionSlot> held;
  for (int i = 0; i < 5; ++i) held.push_back(slots.Acquire(make_address("127.0.0.1"), &refusal));
  for (const ConnectionSlot& s : held) EXPECT_TRUE(s);
  EXPECT_FALSE(slots.Acquire(make_address("127.0.0.1"), &refusal));
  EXPECT_EQ(refusal, Refusal::kTotal);
}

}  // namespace
}  // namespace idms::server
