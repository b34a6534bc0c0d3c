// udp:PORT — the device bridge of protocol/udp_bridge.md. The loop drains the socket without
// blocking at each read and sends one force datagram per write: the device's own I/O, the only
// system calls a tick makes besides the clock.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string>

#include "device_internal.h"
#include "idms/agent/udp_bridge.h"
#include "text_internal.h"

namespace idms::agent {
namespace {

// Datagrams read per tick at most, so a flooding driver cannot stall the loop.
constexpr int kMaxDatagramsPerTick = 64;

class UdpDevice final : public Device {
 public:
  UdpDevice(int fd, int64_t timeout_ticks, std::string name)
      : fd_(fd), timeout_ticks_(timeout_ticks), name_(std::move(name)) {}
  ~UdpDevice() override { ::close(fd_); }

  void Read(int64_t tick, double, DeviceReading* out) override {
    // Drain the socket, keeping the newest valid position and its sender.
    uint8_t buf[kUdpMaxDatagramBytes + 1];
    for (int i = 0; i < kMaxDatagramsPerTick; ++i) {
      sockaddr_in from{};
      socklen_t from_len = sizeof(from);
      const ssize_t n = ::recvfrom(fd_, buf, sizeof(buf), MSG_DONTWAIT, reinterpret_cast<sockaddr*>(&from), &from_len);
      if (n < 0) break;  // EAGAIN: nothing more (other errors: try again next tick)
      UdpPosition msg;
      if (!DecodeUdpPosition(buf, static_cast<size_t>(n), &msg)) {
        ++stats_.invalid;
        continue;
      }
      if (has_position_ && !UdpSequenceNewer(msg.sequence, last_.sequence)) {
        ++stats_.stale;
        continue;
      }
      if (has_position_) stats_.lost += msg.sequence - last_.sequence - 1;
      ++stats_.received;
      last_ = msg;
      has_position_ = true;
      last_tick_ = tick;
      peer_ = from;
      has_peer_ = true;
    }
    // Fresh enough: the device is where the driver said; else no input (force goes to zero).
    timed_out_ = has_position_ && tick - last_tick_ > timeout_ticks_;
    if (timed_out_) ++stats_.timeouts;
    out->valid = has_position_ && !timed_out_;
    out->closed = (last_.flags & kUdpButton) != 0;
    for (int i = 0; i < 3; ++i) out->pos[i] = last_.pos[i];
    out->oriented = last_.oriented;
    for (int i = 0; i < 4; ++i) out->orientation[i] = last_.orientation[i];
    tick_ = tick;
  }

  void Write(int64_t tick, const double force[3]) override {
    if (!has_peer_) return;
    UdpForce msg;
    msg.flags = timed_out_ ? kUdpForceTimeout : kUdpForceActive;
    msg.tick = static_cast<uint64_t>(tick);
    for (int i = 0; i < 3; ++i) msg.force[i] = timed_out_ ? 0.0 : force[i];
    Send(&msg);
  }

  void Release() override {
    if (!has_peer_) return;
    // Zero force, flagged; sent three times because a datagram may be lost.
    UdpForce msg;
    msg.flags = kUdpForceShutdown;
    msg.tick = static_cast<uint64_t>(tick_);
    for (int i = 0; i < 3; ++i) Send(&msg);
  }

  DeviceStats stats() const override { return stats_; }
  const char* name() const override { return name_.c_str(); }

 private:
  void Send(UdpForce* msg) {
    msg->sequence = ++force_sequence_;
    msg->echo_sequence = last_.sequence;
    uint8_t buf[kUdpDatagramBytes];
    EncodeUdpForce(*msg, buf);
    if (::sendto(fd_, buf, sizeof(buf), MSG_DONTWAIT, reinterpret_cast<const sockaddr*>(&peer_), sizeof(peer_)) ==
        static_cast<ssize_t>(sizeof(buf))) {
      ++stats_.sent;
    }
  }

  int fd_;
  int64_t timeout_ticks_;
  std::string name_;
  UdpPosition last_;
  bool has_position_ = false, has_peer_ = false, timed_out_ = false;
  int64_t last_tick_ = 0, tick_ = 0;
  uint32_t force_sequence_ = 0;
  sockaddr_in peer_{};
  DeviceStats stats_;
};

bool ParseInt(std::string_view text, int64_t lo, int64_t hi, int64_t* out) {
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), *out);
  return ec == std::errc() && ptr == text.data() + text.size() && *out >= lo && *out <= hi;
}

}  // namespace

std::unique_ptr<Device> MakeUdpDevice(std::string_view args, double tick_s, std::string* error) {
  // PORT, then options.
  const size_t comma = args.find(',');
  int64_t port = 0, timeout_ms = 50;
  std::string bind_addr = "127.0.0.1";
  if (!ParseInt(args.substr(0, comma), 1, 65535, &port)) {
    *error = Cat({"expected a UDP port in 1..65535, got '", args.substr(0, comma)}) + "'";
    return nullptr;
  }
  std::string_view rest = comma == std::string_view::npos ? std::string_view() : args.substr(comma + 1);
  while (!rest.empty()) {
    const size_t next = rest.find(',');
    const std::string_view item = rest.substr(0, next);
    if (item.substr(0, 5) == "bind=") {
      bind_addr = std::string(item.substr(5));
    } else if (item.substr(0, 11) == "timeout_ms=" && ParseInt(item.substr(11), 1, 60000, &timeout_ms)) {
    } else {
      *error = Cat({"unknown option '", item}) + "' (udp: bind=IPV4, timeout_ms=1..60000)";
      return nullptr;
    }
    rest = next == std::string_view::npos ? std::string_view() : rest.substr(next + 1);
  }
  // Bind the socket now, so a port in use is a start-up error.
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  if (::inet_pton(AF_INET, bind_addr.c_str(), &addr.sin_addr) != 1) {
    *error = "bind address '" + bind_addr + "' is not an IPv4 address";
    return nullptr;
  }
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  if (fd < 0 || ::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
    *error = "cannot bind UDP " + bind_addr + ":" + std::to_string(port) + ": " + std::strerror(errno);
    if (fd >= 0) ::close(fd);
    return nullptr;
  }
  const int64_t timeout_ticks = std::max<int64_t>(1, std::llround(1e-3 * static_cast<double>(timeout_ms) / tick_s));
  return std::make_unique<UdpDevice>(fd, timeout_ticks, "udp:" + std::to_string(port));
}

}  // namespace idms::agent
