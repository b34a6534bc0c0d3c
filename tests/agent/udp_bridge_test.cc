// The UDP bridge (protocol/udp_bridge.md): datagram packing, and the real idms-agent driven by a
// fake device driver — force comes back for a pressed position, goes to zero on a timeout, and is
// zeroed and flagged at shutdown.
#include "idms/agent/udp_bridge.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>

#include "agent_process.h"
#include "idms/agent/setup.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms::test {
namespace {

using agent::UdpForce;
using agent::UdpPosition;

TEST(UdpBridge, DatagramsRoundTripLittleEndian) {
  UdpPosition p;
  p.flags = agent::kUdpButton;
  p.sequence = 0xfffffffe;
  p.driver_time_ns = 123456789;
  p.pos[0] = 1.5, p.pos[1] = -2.25, p.pos[2] = 3e-3;
  uint8_t buf[agent::kUdpMaxDatagramBytes];
  ASSERT_EQ(agent::EncodeUdpPosition(p, buf), agent::kUdpDatagramBytes);
  EXPECT_EQ(buf[0], 'I');
  EXPECT_EQ(buf[3], 'P');
  EXPECT_EQ(buf[8], 0xfe);  // sequence, least significant byte first
  UdpPosition q;
  ASSERT_TRUE(agent::DecodeUdpPosition(buf, agent::kUdpDatagramBytes, &q));
  EXPECT_EQ(q.sequence, p.sequence);
  EXPECT_EQ(q.flags, p.flags);
  EXPECT_EQ(q.driver_time_ns, p.driver_time_ns);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(q.pos[i], p.pos[i]);
  // Wrong size, a force datagram, a NaN: rejected.
  EXPECT_FALSE(agent::DecodeUdpPosition(buf, agent::kUdpDatagramBytes - 1, &q));
  UdpForce f;
  f.force[2] = 0.5;
  agent::EncodeUdpForce(f, buf);
  EXPECT_FALSE(agent::DecodeUdpPosition(buf, agent::kUdpDatagramBytes, &q));
  UdpForce g;
  ASSERT_TRUE(agent::DecodeUdpForce(buf, agent::kUdpDatagramBytes, &g));
  EXPECT_EQ(g.force[2], 0.5);
  p.pos[1] = std::nan("");
  agent::EncodeUdpPosition(p, buf);
  EXPECT_FALSE(agent::DecodeUdpPosition(buf, agent::kUdpDatagramBytes, &q));
}

TEST(UdpBridge, AnOrientedPositionIsVersionTwoAndEightyBytes) {
  UdpPosition p;
  p.sequence = 9;
  p.pos[2] = 1;
  p.oriented = true;
  p.orientation[0] = 0.5, p.orientation[1] = 0.5, p.orientation[2] = -0.5, p.orientation[3] = 0.5;
  uint8_t buf[agent::kUdpMaxDatagramBytes];
  ASSERT_EQ(agent::EncodeUdpPosition(p, buf), 80u);
  EXPECT_EQ(buf[4], 2);  // version
  UdpPosition q;
  ASSERT_TRUE(agent::DecodeUdpPosition(buf, 80, &q));
  EXPECT_TRUE(q.oriented);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(q.orientation[i], p.orientation[i]);
  EXPECT_EQ(q.pos[2], 1);
  // Version 2 at version 1's size, version 1 at 80 bytes, a zero or NaN orientation: refused.
  EXPECT_FALSE(agent::DecodeUdpPosition(buf, 48, &q));
  p.oriented = false;
  ASSERT_EQ(agent::EncodeUdpPosition(p, buf), 48u);
  EXPECT_FALSE(agent::DecodeUdpPosition(buf, 80, &q));
  ASSERT_TRUE(agent::DecodeUdpPosition(buf, 48, &q));
  EXPECT_FALSE(q.oriented);
  p.oriented = true;
  for (double& c : p.orientation) c = 0;
  agent::EncodeUdpPosition(p, buf);
  EXPECT_FALSE(agent::DecodeUdpPosition(buf, 80, &q));
  p.orientation[0] = std::nan("");
  agent::EncodeUdpPosition(p, buf);
  EXPECT_FALSE(agent::DecodeUdpPosition(buf, 80, &q));
}

TEST(UdpBridge, SequenceOrderSurvivesWrap) {
  EXPECT_TRUE(agent::UdpSequenceNewer(1, 0));
  EXPECT_TRUE(agent::UdpSequenceNewer(0, 0xffffffff));
  EXPECT_FALSE(agent::UdpSequenceNewer(5, 5));
  EXPECT_FALSE(agent::UdpSequenceNewer(4, 5));
}

// A fake driver: one UDP socket talking to the agent's port.
class FakeDriver {
 public:
  explicit FakeDriver(uint16_t agent_port) {
    fd_ = socket(AF_INET, SOCK_DGRAM, 0);
    agent_.sin_family = AF_INET;
    agent_.sin_port = htons(agent_port);
    inet_pton(AF_INET, "127.0.0.1", &agent_.sin_addr);
  }
  ~FakeDriver() { close(fd_); }

  // With an orientation (w, x, y, z), a version-2 datagram.
  void SendPosition(const double pos[3], bool button = false, const double* orientation = nullptr) {
    UdpPosition p;
    p.sequence = ++sequence_;
    p.flags = button ? agent::kUdpButton : 0;
    for (int i = 0; i < 3; ++i) p.pos[i] = pos[i];
    if (orientation) {
      p.oriented = true;
      for (int i = 0; i < 4; ++i) p.orientation[i] = orientation[i];
    }
    uint8_t buf[agent::kUdpMaxDatagramBytes];
    SendRaw(buf, agent::EncodeUdpPosition(p, buf));
  }
  void SendRaw(const uint8_t* data, size_t size) {
    sendto(fd_, data, size, 0, reinterpret_cast<const sockaddr*>(&agent_), sizeof(agent_));
  }
  // The newest force datagram once at least one is there, waiting up to timeout_ms for it.
  bool ReceiveForce(UdpForce* out, int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return false;
    bool any = false;
    uint8_t buf[64];
    ssize_t n = 0;
    while ((n = recv(fd_, buf, sizeof(buf), MSG_DONTWAIT)) > 0) {
      any = agent::DecodeUdpForce(buf, static_cast<size_t>(n), out) || any;
    }
    return any;
  }
  // Servo loop: one position per force received, until pred(force) or `max` exchanges.
  bool ServoUntil(const double pos[3], const std::function<bool(const UdpForce&)>& pred, int max) {
    for (int i = 0; i < max; ++i) {
      SendPosition(pos);
      UdpForce f;
      if (ReceiveForce(&f, 1000) && pred(f)) return true;
    }
    return false;
  }
  uint32_t sequence() const { return sequence_; }

 private:
  int fd_ = -1;
  sockaddr_in agent_{};
  uint32_t sequence_ = 0;
};

uint16_t FreeUdpPort() {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
  bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof(a));
  socklen_t len = sizeof(a);
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  close(fd);
  return ntohs(a.sin_port);
}

TEST(UdpBridge, FakeDriverGetsForceTimeoutAndShutdown) {
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  Model model;
  LoadError load_error;
  ASSERT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", ReadOptions{}, &model, &load_error));
  const ScriptGeometry g = MakeScriptGeometry(model, 1.5);
  // Identity registration: device coordinates are model coordinates.
  const double hover[3] = {g.center[0], g.center[1], g.top_z + 2.5};
  const double pressed[3] = {g.center[0], g.center[1], g.top_z + 1.5 - 0.05};  // under the 8 N clamp

  const uint16_t port = FreeUdpPort();
  const std::string dir = TempDir("udp");
  AgentProcess agent({"--server", "none", "--model-file", prefix, "--device", "udp:" + std::to_string(port),
                      "--no-realtime", "--summary-json", dir + "/summary.json"},
                     dir + "/agent.log");
  ASSERT_TRUE(agent.started());
  FakeDriver driver(port);

  // Hovering: the agent answers (once its socket is up) with zero force, echoing our sequence.
  ASSERT_TRUE(driver.ServoUntil(
      hover,
      [&](const UdpForce& f) {
        return (f.flags & agent::kUdpForceActive) != 0 && f.echo_sequence == driver.sequence();
      },
      3000))
      << agent.Log();
  // Pressed into the surface over half a second, as a hand would, then held: the force pushes
  // the tool back up (+z) and settles to the static force.
  for (int i = 1; i <= 500; ++i) {
    const double u = i / 500.0;
    const double pos[3] = {hover[0], hover[1], hover[2] + u * (pressed[2] - hover[2])};
    driver.SendPosition(pos);
    UdpForce f;
    ASSERT_TRUE(driver.ReceiveForce(&f, 1000));
  }
  double min_fz = 1e9, max_fz = -1e9;
  for (int i = 0; i < 300; ++i) {
    driver.SendPosition(pressed);
    UdpForce f;
    ASSERT_TRUE(driver.ReceiveForce(&f, 1000));
    if (i >= 100) min_fz = std::min(min_fz, f.force[2]), max_fz = std::max(max_fz, f.force[2]);
  }
  // Held still, the tissue comes to rest: the force is the static one, the same as the step's own
  // when it holds the tool there (the agent's built-in scene, run in-process), and steady.
  double static_fz = 0;
  {
    StepOptions step;
    ToolCommand tool;
    agent::Registration reg;
    std::string error;
    ASSERT_TRUE(agent::SceneToLoop(agent::DefaultScene("palpate"), &step, &tool, &reg, &error)) << error;
    State state = MakeState(model);
    Workspace workspace = MakeWorkspace(model, step);
    ToolInput input;
    input.num_tools = 1;
    for (int i = 1; i <= 3000; ++i) {
      const double u = std::min(1.0, i / 500.0);
      input.tools[0] = tool;
      for (int c = 0; c < 3; ++c) input.tools[0].pos[c] = hover[c] + u * (pressed[c] - hover[c]);
      static_fz = Step(model, state, workspace, input).tools[0].force[2];
    }
  }
  std::printf("[ figures  ] held 0.05 below contact: f_z %.4f to %.4f N over UDP, %.4f N in-process\n", min_fz, max_fz,
              static_fz);
  EXPECT_GT(static_fz, 1.0);
  EXPECT_NEAR(min_fz, static_fz, 0.01 * static_fz);
  EXPECT_NEAR(max_fz, static_fz, 0.01 * static_fz);
  // A malformed datagram is ignored (and counted).
  const uint8_t junk[5] = {1, 2, 3, 4, 5};
  driver.SendRaw(junk, sizeof(junk));
  // Silence: past the 50 ms timeout the agent sends zero force flagged TIMEOUT.
  UdpForce f;
  bool timed_out = false;
  for (int i = 0; i < 1000 && !timed_out; ++i) {
    ASSERT_TRUE(driver.ReceiveForce(&f, 1000));
    timed_out = (f.flags & agent::kUdpForceTimeout) != 0;
  }
  ASSERT_TRUE(timed_out);
  EXPECT_EQ(f.force[0], 0.0);
  EXPECT_EQ(f.force[1], 0.0);
  EXPECT_EQ(f.force[2], 0.0);
  // Back in contact, then SIGTERM: the last datagram says SHUTDOWN with zero force.
  ASSERT_TRUE(driver.ServoUntil(
      pressed, [](const UdpForce& g2) { return g2.force[2] > 0.1; }, 3000));
  agent.Signal(SIGTERM);
  bool shutdown = false;
  while (!shutdown && driver.ReceiveForce(&f, 5000)) shutdown = (f.flags & agent::kUdpForceShutdown) != 0;
  ASSERT_TRUE(shutdown) << agent.Log();
  EXPECT_EQ(f.force[0], 0.0);
  EXPECT_EQ(f.force[1], 0.0);
  EXPECT_EQ(f.force[2], 0.0);
  ASSERT_EQ(agent.Wait(std::chrono::seconds(30)), std::optional<int>(0)) << agent.Log();
  const nlohmann::json summary = nlohmann::json::parse(ReadText(dir + "/summary.json"));
  EXPECT_GE(summary["device_stats"]["invalid"], 1);
  EXPECT_GE(summary["device_stats"]["timeouts"], 1);
  EXPECT_GT(summary["device_stats"]["received"], 100);
  EXPECT_EQ(summary["force_faults"], 0);
}

}  // namespace
}  // namespace idms::test
