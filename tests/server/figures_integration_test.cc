// The figures an instructor grades from (issue 28, "trust the figures"), against the real
// idms-server: a session's summary describes its whole recording across a kill -9, a restart and
// a resume, every event carries its session time, and a session names its trainee.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <ctime>
#include <fstream>
#include <nlohmann/json.hpp>

#include "idms/protocol/envelope.h"
#include "server_process.h"
#include "session_checks.h"
#include "test_clients.h"

namespace idms::test {
namespace {

using json = nlohmann::json;
using std::chrono::seconds;

// Ticks first..first+n-1 at 1 kHz (time (tick + 1) ms), in contact, with a force of `force`
// except at `peak_tick` (force `peak`, at the device's limit, one numerical warning, slipping).
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
    if (tick == peak_tick) {
      s->set_warnings(1), s->set_force_limited(true);
      s->mutable_friction_force()->set_x(0.3);  // and slipping, with friction (issue 30)
      s->set_normal_force(1.0);
      s->set_friction(v1::FRICTION_SLIP);
    }
  }
  return agent.Send(e);
}

// Today's UTC date, "2026-11-27".
std::string UtcDate() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[16];
  std::strftime(buf, sizeof buf, "%Y-%m-%d", &tm);
  return buf;
}

// A new session opened by `agent`: its id, empty when no Welcome came.
std::string NewSession(FakeAgent& agent) {
  const auto welcome = agent.Hello();
  return welcome && welcome->has_welcome() ? welcome->welcome().session_id() : std::string();
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
    ASSERT_TRUE(
        agent.ReadUntil([](const v1::Envelope& e) { return e.has_ack() && e.ack().next_tick() == 1000; }, seconds(20)));
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

  // The samples as CSV: every tick once, the peak where it was.
  const HttpReply csv = Get(server->port(), "/api/sessions/" + id + "/samples.csv", observer);
  ASSERT_EQ(csv.status, 200);
  EXPECT_EQ(csv.headers.at("content-type"), "text/csv; charset=utf-8");
  EXPECT_EQ(std::count(csv.body.begin(), csv.body.end(), '\n'), 2001) << csv.body.substr(0, 300);
  EXPECT_EQ(csv.body.substr(0, csv.body.find('\n')),
            "tick,time_s,x,y,z,fx,fy,fz,contact,force_limited,num_contacts,warnings,ftx,fty,ftz,ft,fn,friction");
  EXPECT_NE(csv.body.find("\n500,0.501,0,0,1.4,0,0,8,1,1,0,1,0.3,0,0,0.3,1,slip\n"), std::string::npos);
  EXPECT_NE(csv.body.find("\n501,0.502,0,0,1.4,0,0,1,1,0,0,0,0,0,0,0,0,none\n"), std::string::npos);

  // The force over the whole session in 100 slices (a plot's): the peak kept where it was.
  const HttpReply profile = Get(server->port(), "/api/sessions/" + id + "/force?points=100", observer);
  ASSERT_EQ(profile.status, 200) << profile.body;
  const json force = json::parse(profile.body);
  ASSERT_EQ(force["time_s"].size(), force["force"].size());
  EXPECT_GE(force["time_s"].size(), 95u);
  EXPECT_LE(force["time_s"].size(), 100u);
  const std::vector<double> times = force["time_s"], forces = force["force"];
  EXPECT_TRUE(std::is_sorted(times.begin(), times.end()));
  const size_t peak_at = std::max_element(forces.begin(), forces.end()) - forces.begin();
  EXPECT_DOUBLE_EQ(forces[peak_at], 8.0);
  EXPECT_DOUBLE_EQ(times[peak_at], 0.501);
  EXPECT_DOUBLE_EQ(forces.front(), 1.0);
  for (const char* bad : {"?points=9", "?points=10001", "?points=x", "?points="}) {
    EXPECT_EQ(Get(server->port(), "/api/sessions/" + id + "/force" + bad, observer).status, 400) << bad;
  }
  EXPECT_EQ(Get(server->port(), "/api/sessions/none/force", observer).status, 404);

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

// A session names its trainee (the agent's --trainee), an admin corrects it, and the list filters
// by trainee, model and date.
TEST(Figures, ATraineeNamesTheSessionAndTheListFiltersByTraineeModelAndDate) {
  const std::string dir = TempDir("figures-trainee");
  auto server = std::make_unique<ServerProcess>(dir + "/data");
  ASSERT_TRUE(server->ready()) << server->Log();
  const std::string port = server->port_string(), observer = server->Token("observer"), admin = server->Token("admin");
  std::ofstream(dir + "/agent.token") << server->Token("agent");
  const auto run = [&](const std::string& trainee, const std::string& model) {
    ChildProcess agent(
        IDMS_AGENT_BIN,
        {"--server", "ws://127.0.0.1:" + port, "--token-file", dir + "/agent.token", "--model", model, "--cache-dir",
         dir + "/cache", "--device", "scripted:palpate", "--duration", "0.3", "--no-realtime", "--trainee", trainee},
        dir + "/agent-" + trainee + ".log");
    return agent.Wait(seconds(120));
  };
  ASSERT_EQ(run("Ada Lovelace", "hex_4x5_home"), 0);
  ASSERT_EQ(run("Bo", "sphere_cap"), 0);
  const auto ids = [&](const std::string& query) {
    const HttpReply r = Get(server->port(), "/api/sessions" + query, observer);
    std::vector<std::string> out;
    if (r.status != 200) return std::vector<std::string>{"HTTP " + std::to_string(r.status)};
    const json body = json::parse(r.body);
    for (const json& s : body["sessions"]) out.push_back(s["trainee"].get<std::string>());
    return out;
  };
  ASSERT_TRUE(Eventually([&] { return ids("").size() == 2; }));
  EXPECT_EQ(ids(""), (std::vector<std::string>{"Bo", "Ada Lovelace"}));
  EXPECT_EQ(ids("?trainee=Ada%20Lovelace"), std::vector<std::string>{"Ada Lovelace"});
  EXPECT_EQ(ids("?model=sphere_cap"), std::vector<std::string>{"Bo"});
  const std::string today = UtcDate();
  EXPECT_EQ(ids("?from=" + today + "&to=" + today).size(), 2u);
  EXPECT_TRUE(ids("?from=2999-01-01").empty());
  EXPECT_TRUE(ids("?to=2000-01-01").empty());

  // An admin corrects the name; an observer may not; a bad body or an unknown session is refused.
  const json ada = json::parse(Get(server->port(), "/api/sessions?trainee=Ada%20Lovelace", observer).body);
  const std::string id = ada["sessions"][0]["id"];
  const auto patch = [&](const std::string& token, const std::string& target, const std::string& body) {
    return Http(
        server->port(),
        HttpCall{"PATCH", target, {{"Authorization", "Bearer " + token}, {"Content-Type", "application/json"}}, body});
  };
  const HttpReply ok = patch(admin, "/api/sessions/" + id, R"({"trainee": "Ada King"})");
  EXPECT_EQ(ok.status, 200) << ok.body;
  EXPECT_EQ(json::parse(ok.body)["trainee"], "Ada King");
  EXPECT_EQ(patch(observer, "/api/sessions/" + id, R"({"trainee": "x"})").status, 403);
  EXPECT_EQ(patch(admin, "/api/sessions/" + id, R"({"name": "x"})").status, 400);
  EXPECT_EQ(patch(admin, "/api/sessions/" + id, "{\"trainee\": \"a\\nb\"}").status, 400);
  EXPECT_EQ(patch(admin, "/api/sessions/" + id, R"({"trainee": ")" + std::string(300, 'x') + "\"}").status, 400);
  EXPECT_EQ(patch(admin, "/api/sessions/nope", R"({"trainee": "x"})").status, 404);
  // It survives a restart.
  server.reset();
  server = std::make_unique<ServerProcess>(dir + "/data", std::vector<std::string>{"--listen", "127.0.0.1:" + port});
  ASSERT_TRUE(server->ready()) << server->Log();
  EXPECT_EQ(ids("?trainee=Ada%20King"), std::vector<std::string>{"Ada King"});
}

// A scene names limits; each session shows how it did against them (and one without is not graded).
TEST(Figures, ASessionIsGradedAgainstItsScenesLimits) {
  const std::string dir = TempDir("figures-grading");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string observer = server.Token("observer");
  const auto session = [&](bool graded) {
    FakeAgent agent(server.port(), server.Token("agent"));
    v1::Envelope hello;
    v1::Hello* h = hello.mutable_hello();
    h->set_protocol_version(kProtocolVersion);
    h->set_role(v1::ROLE_AGENT);
    h->mutable_scene()->set_model("hex_4x5_home");
    if (graded) {
      v1::Grading* g = h->mutable_scene()->mutable_grading();
      g->set_max_peak_force(5);
      g->set_max_contact_time_s(10);
      g->set_max_force_limit_hits(0);
      h->mutable_scene()->mutable_units()->set_mm_per_unit(25.4);
    }
    EXPECT_TRUE(agent.Send(hello));
    const auto welcome = agent.ReadUntil([](const v1::Envelope& e) { return e.has_welcome(); });
    EXPECT_TRUE(welcome);
    if (!welcome) return std::string();
    EXPECT_TRUE(SendPress(agent, 0, 1000, 1.0, 500, 8.0));
    EXPECT_TRUE(agent.End(999));
    return welcome->welcome().session_id();
  };
  const std::string graded = session(true), plain = session(false);
  const json row = Row(server.port(), observer, graded);
  ASSERT_TRUE(row["grade"].is_object()) << row.dump();
  EXPECT_EQ(row["grade"]["passed"], false);
  std::map<std::string, bool> passed;
  for (const json& c : row["grade"]["checks"]) passed[c["figure"].get<std::string>()] = c["passed"].get<bool>();
  EXPECT_EQ(passed, (std::map<std::string, bool>{
                        {"contact_time_s", true}, {"force_limit_hits", false}, {"peak_force", false}}));
  EXPECT_TRUE(Row(server.port(), observer, plain)["grade"].is_null());
  // The units the scene declares, for the pages to convert (none: an empty object).
  EXPECT_EQ(row["units"], json({{"mm_per_unit", 25.4}}));
  EXPECT_EQ(Row(server.port(), observer, plain)["units"], json::object());
  // The session's own page says the same.
  const HttpReply detail = Get(server.port(), "/api/sessions/" + graded, observer);
  ASSERT_EQ(detail.status, 200);
  EXPECT_EQ(json::parse(detail.body)["grade"]["passed"], false);
}

// A viewer who joins a live session late sees the events and notes from before it joined (not the
// other viewers' comings and goings), in order.
TEST(Figures, AViewerWhoJoinsLateSeesTheEarlierEventsAndNotes) {
  const std::string dir = TempDir("figures-late");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  FakeAgent agent(server.port(), server.Token("agent"));
  const std::string id = NewSession(agent);
  ASSERT_FALSE(id.empty());
  ASSERT_TRUE(SendPress(agent, 0, 500, 1.0));
  v1::Envelope warning;
  warning.mutable_session_event()->set_kind(v1::SessionEvent::KIND_WARNING);
  warning.mutable_session_event()->set_time_s(0.4);
  warning.mutable_session_event()->set_message("a warning before anyone watched");
  ASSERT_TRUE(agent.Send(warning));
  {
    TestViewer early(server.port(), id, server.Token("admin"));
    // It has the warning (as history: the agent's frames and this viewer's are not ordered).
    ASSERT_TRUE(Eventually([&] {
      for (const v1::Envelope& f : early.Frames()) {
        if (f.has_session_event() && f.session_event().kind() == v1::SessionEvent::KIND_WARNING) return true;
      }
      return false;
    }));
    v1::Envelope note;
    note.mutable_annotation()->set_text("pressed too hard");
    note.mutable_annotation()->set_time_s(0.45);
    early.Send(note);
    ASSERT_TRUE(Eventually([&] {
      for (const v1::Envelope& f : early.Frames()) {
        if (f.has_annotation()) return true;
      }
      return false;
    }));
  }
  TestViewer late(server.port(), id, server.Token("observer"));
  std::vector<std::string> seen;
  ASSERT_TRUE(Eventually([&] {
    seen.clear();
    for (const v1::Envelope& f : late.Frames()) {
      if (f.has_annotation()) seen.push_back("note: " + f.annotation().text());
      if (f.has_session_event() && f.session_event().kind() != v1::SessionEvent::KIND_VIEWER_JOINED &&
          f.session_event().kind() != v1::SessionEvent::KIND_VIEWER_LEFT) {
        seen.push_back(v1::SessionEvent::Kind_Name(f.session_event().kind()));
      }
    }
    return seen.size() >= 3;
  })) << seen.size();
  EXPECT_EQ(seen, (std::vector<std::string>{"KIND_STARTED", "KIND_WARNING", "note: pressed too hard"}));
}

// Rewind a live session: its replay plays what was recorded up to when it opened (once a 404).
TEST(Figures, ALiveSessionCanBeRewound) {
  const std::string dir = TempDir("figures-rewind");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  FakeAgent agent(server.port(), server.Token("agent"));
  const std::string id = NewSession(agent);
  ASSERT_FALSE(id.empty());
  for (uint64_t t = 0; t < 2000; t += 100) ASSERT_TRUE(SendPress(agent, t, 100, 1.0));
  ASSERT_TRUE(
      agent.ReadUntil([](const v1::Envelope& e) { return e.has_ack() && e.ack().next_tick() == 2000; }, seconds(20)));
  FakeAgent replay(server.port(), server.Token("observer"), "/ws/replay/" + id);
  ASSERT_TRUE(replay.connected());
  ASSERT_TRUE(replay.ReadUntil([](const v1::Envelope& e) { return e.has_welcome(); }));
  v1::Envelope play;
  play.mutable_playback_control()->set_action(v1::PlaybackControl::ACTION_SET_SPEED);
  play.mutable_playback_control()->set_speed(16);
  ASSERT_TRUE(replay.Send(play));
  play.mutable_playback_control()->set_action(v1::PlaybackControl::ACTION_PLAY);
  ASSERT_TRUE(replay.Send(play));
  const auto last = replay.ReadUntil(
      [](const v1::Envelope& e) {
        return e.has_device_samples() && e.device_samples().samples_size() > 0 &&
               e.device_samples().samples(e.device_samples().samples_size() - 1).tick() == 1999;
      },
      seconds(20));
  EXPECT_TRUE(last) << "the replay did not reach the last acknowledged tick";
  // The session is still live meanwhile.
  EXPECT_EQ(Row(server.port(), server.Token("observer"), id)["state"], "live");
}

}  // namespace

HttpReply PostNote(uint16_t port, const std::string& token, const std::string& id, const std::string& body) {
  return Http(port, HttpCall{"POST",
                             "/api/sessions/" + id + "/notes",
                             {{"Authorization", "Bearer " + token}, {"Content-Type", "application/json"}},
                             body});
}

// The notes an instructor adds during a replay (issue 28: "the notes as a list that jumps to their
// time, addable during replay"): a live session takes them as it takes a viewer's, an ended one
// keeps them beside its recording, ids carry on across a restart, and the session's page lists
// them all by time.
TEST(Figures, NotesAreAddedLiveAndInReplayAndListedByTimeAcrossARestart) {
  const std::string dir = TempDir("figures-notes");
  auto server = std::make_unique<ServerProcess>(dir + "/data");
  ASSERT_TRUE(server->ready()) << server->Log();
  const std::string port = server->port_string(), observer = server->Token("observer"), admin = server->Token("admin");
  std::string id;
  {
    FakeAgent agent(server->port(), server->Token("agent"));
    id = NewSession(agent);
    ASSERT_FALSE(id.empty());
    ASSERT_TRUE(SendPress(agent, 0, 1000, 1.0));
    {
      // Live, through the API (a rewound replay's page adds them so): recorded and broadcast. (The
      // viewer goes before the session ends: TestViewer's destructor and its reader thread's
      // teardown of a connection the server closes would race, as ThreadSanitizer sees.)
      TestViewer viewer(server->port(), id, observer);
      const HttpReply live = PostNote(server->port(), observer, id, R"({"time_s": 0.8, "text": "live, at 0.8 s"})");
      ASSERT_EQ(live.status, 201) << live.body;
      EXPECT_EQ(json::parse(live.body)["id"], 1);
      ASSERT_TRUE(Eventually([&] {
        for (const v1::Envelope& f : viewer.Frames()) {
          if (f.has_annotation() && f.annotation().text() == "live, at 0.8 s") return true;
        }
        return false;
      }));
    }
    ASSERT_TRUE(agent.End(999));
  }
  ASSERT_TRUE(Eventually([&] { return Row(server->port(), observer, id)["state"] == "ended"; })) << server->Log();
  // Ended: kept in the index, with the next id.
  const HttpReply replay = PostNote(server->port(), admin, id, R"({"time_s": 0.25, "text": "replay, at 0.25 s"})");
  ASSERT_EQ(replay.status, 201) << replay.body;
  EXPECT_EQ(json::parse(replay.body)["id"], 2);
  EXPECT_EQ(json::parse(replay.body)["author"].get<std::string>().rfind("admin ", 0), 0u) << replay.body;
  // Bad notes change nothing and say what is wrong.
  EXPECT_EQ(PostNote(server->port(), admin, id, R"({"time_s": 1})").status, 400);
  EXPECT_EQ(PostNote(server->port(), admin, id, R"({"text": 7})").status, 400);
  EXPECT_EQ(PostNote(server->port(), admin, id, "not json").status, 400);
  EXPECT_EQ(PostNote(server->port(), admin, id, json{{"text", std::string(1001, 'x')}}.dump()).status, 400);
  EXPECT_EQ(PostNote(server->port(), admin, id, R"({"time_s": -1, "text": "before the start"})").status, 400);
  EXPECT_EQ(PostNote(server->port(), admin, "no-such-session", R"({"text": "x"})").status, 404);
  EXPECT_EQ(PostNote(server->port(), "wrong-token", id, R"({"text": "x"})").status, 401);

  // After a restart: both, by time, and the next note gets the next id.
  server.reset();
  server = std::make_unique<ServerProcess>(dir + "/data", std::vector<std::string>{"--listen", "127.0.0.1:" + port});
  ASSERT_TRUE(server->ready()) << server->Log();
  const HttpReply third = PostNote(server->port(), observer, id, R"({"time_s": 0.5, "text": "after the restart"})");
  ASSERT_EQ(third.status, 201) << third.body;
  EXPECT_EQ(json::parse(third.body)["id"], 3);
  const HttpReply detail = Get(server->port(), "/api/sessions/" + id, observer);
  ASSERT_EQ(detail.status, 200);
  std::vector<std::string> listed;
  const json session = json::parse(detail.body);
  for (const json& n : session["annotations"]) {
    listed.push_back(std::to_string(n["id"].get<int>()) + " " + n["text"].get<std::string>());
  }
  EXPECT_EQ(listed, (std::vector<std::string>{"2 replay, at 0.25 s", "3 after the restart", "1 live, at 0.8 s"}));
  // A deleted session takes its notes with it.
  ASSERT_EQ(
      Http(server->port(), HttpCall{"DELETE", "/api/sessions/" + id, {{"Authorization", "Bearer " + admin}}}).status,
      200);
  EXPECT_EQ(PostNote(server->port(), admin, id, R"({"text": "x"})").status, 404);
}

}  // namespace idms::test
