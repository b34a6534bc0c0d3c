// The figures an instructor grades from (issue 28, "trust the figures"), against the real
// idms-server: a session's summary describes its whole recording across a kill -9, a restart and
// a resume, and every event carries its session time.
#include <gtest/gtest.h>
#include <signal.h>

#include <nlohmann/json.hpp>

#include "server_process.h"
#include "session_checks.h"
#include "test_clients.h"

namespace idms::test {
namespace {

using json = nlohmann::json;
using std::chrono::seconds;

// Ticks first..first+n-1 at 1 kHz (time (tick + 1) ms), in contact, with a force of `force`
// except at `peak_tick` (force `peak`, at the device's limit, one numerical warning).
bool SendPress(FakeAgent& agent, uint64_t first, int n, double force, uint64_t peak_tick = UINT64_MAX,
               double peak = 0) {
  v1::Envelope e;
  for (int i = 0; i < n; ++i) {
    const uint64_t tick = first + static_cast<uint64_t>(i);
    v1::DeviceSample* s = e.mutable_device_samples()->add_samples();
    s->set_tick(tick);
    s->set_time_s(static_cast<double>(tick + 1) * 0.001);
    s->set_contact(true);
    s->mutable_tool_pos()->set_z(1.4);
    s->mutable_force()->set_z(tick == peak_tick ? peak : force);
    if (tick == peak_tick) s->set_warnings(1), s->set_force_limited(true);
  }
  return agent.Send(e);
}

json Row(uint16_t port, const std::string& token, const std::string& id) {
  for (const json& s : Sessions(port, token)) {
    if (s["id"] == id) return s;
  }
  return json();
}

// The session list once showed, after a kill -9 and a restart, only what followed the restart
// (206.5 s of a 676 s recording, its peak and warning forgotten), and the resume and end events
// had time 0.
TEST(Figures, TheSummaryDescribesTheWholeRecordingAcrossAKillARestartAndAResume) {
  const std::string dir = TempDir("figures-restart");
  auto server = std::make_unique<ServerProcess>(dir + "/data");
  ASSERT_TRUE(server->ready()) << server->Log();
  const std::string port = server->port_string(), observer = server->Token("observer"),
                    agent_token = server->Token("agent");
  std::string id, resume_token;
  {
    FakeAgent agent(server->port(), agent_token);
    const auto welcome = agent.Hello();
    ASSERT_TRUE(welcome && welcome->has_welcome());
    id = welcome->welcome().session_id();
    resume_token = welcome->welcome().resume_token();
    // 1 s in contact at 1 N, with an 8 N peak and a warning at 0.5 s.
    for (uint64_t t = 0; t < 1000; t += 100) ASSERT_TRUE(SendPress(agent, t, 100, 1.0, 500, 8.0));
    // Stored: the server acknowledges every tick (its recording flushed).
    ASSERT_TRUE(agent.ReadUntil([](const v1::Envelope& e) { return e.has_ack() && e.ack().next_tick() == 1000; },
                                seconds(20)));
    server->process().Signal(SIGKILL);
    ASSERT_TRUE(server->process().Wait(seconds(30)));
  }
  server = std::make_unique<ServerProcess>(dir + "/data", std::vector<std::string>{"--listen", "127.0.0.1:" + port});
  ASSERT_TRUE(server->ready()) << server->Log();
  const json repaired = Row(server->port(), observer, id);
  ASSERT_FALSE(repaired.is_null());
  EXPECT_EQ(repaired["state"], "interrupted");
  EXPECT_DOUBLE_EQ(repaired["summary"]["peak_force"].get<double>(), 8.0) << repaired.dump();
  EXPECT_EQ(repaired["summary"]["warnings"].get<int>(), 1);
  EXPECT_NEAR(repaired["duration_s"].get<double>(), 0.999, 1e-6);

  // The agent resumes and carries on for another second at 1 N, then ends (an ENDED without a time,
  // as agents sent it before).
  FakeAgent agent(server->port(), agent_token);
  const auto welcome = agent.Hello(id, resume_token);
  ASSERT_TRUE(welcome && welcome->has_welcome()) << (welcome ? welcome->DebugString() : "no answer");
  ASSERT_EQ(welcome->welcome().next_tick(), 1000u);
  for (uint64_t t = 1000; t < 2000; t += 100) ASSERT_TRUE(SendPress(agent, t, 100, 1.0));
  ASSERT_TRUE(agent.End(1999));

  ASSERT_TRUE(Eventually([&] { return Row(server->port(), observer, id)["state"] == "ended"; })) << server->Log();
  const json row = Row(server->port(), observer, id);
  EXPECT_EQ(row["samples"].get<int>(), 2000);
  EXPECT_NEAR(row["duration_s"].get<double>(), 1.999, 1e-6) << "the whole recording, not what followed the restart";
  EXPECT_DOUBLE_EQ(row["summary"]["peak_force"].get<double>(), 8.0) << "the peak before the restart";
  EXPECT_EQ(row["summary"]["warnings"].get<int>(), 1);
  EXPECT_EQ(row["summary"]["force_limit_hits"].get<int>(), 1);
  EXPECT_NEAR(row["summary"]["force_limited_s"].get<double>(), 0.001, 1e-9);
  EXPECT_NEAR(row["summary"]["contact_time_s"].get<double>(), 1.999, 1e-6);
  EXPECT_NEAR(row["summary"]["mean_contact_force"].get<double>(), (1999 * 1.0 + 8.0) / 2000, 1e-9);

  // Every event at its session time: started at 0, resumed at 1 s, ended at 2 s.
  const HttpReply detail = Get(server->port(), "/api/sessions/" + id, observer);
  ASSERT_EQ(detail.status, 200);
  std::map<std::string, double> at;
  const json body = json::parse(detail.body);
  for (const json& e : body["events"]) at[e["kind"].get<std::string>()] = e["time_s"].get<double>();
  ASSERT_TRUE(at.count("KIND_AGENT_RESUMED") && at.count("KIND_ENDED")) << detail.body;
  EXPECT_NEAR(at["KIND_AGENT_RESUMED"], 1.0, 1e-9);
  EXPECT_NEAR(at["KIND_ENDED"], 2.0, 1e-9);
}

}  // namespace
}  // namespace idms::test
