// The shared recorded session: idms-server on a free port, idms-agent with scripted:palpate for
// 3 s (the palpation reaches contact), the recording downloaded, its peak force and the last
// moment before contact located.
#include "recording_fixture.h"

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "idms/protocol/recording.h"

namespace idms::test {
namespace {

using json = nlohmann::json;

void Make(RecordedSession* s) {
  s->dir = TempDir("render-session");
  s->server = std::make_unique<ServerProcess>(s->dir + "/data", std::vector<std::string>{"--workers", "8"});
  if (!s->server->ready()) return void(s->error = "server: " + s->server->Log());
  const std::string observer = s->server->Token("observer");
  ChildProcess agent(IDMS_AGENT_BIN,
                     {"--server", "ws://127.0.0.1:" + s->server->port_string(), "--token", s->server->Token("agent"),
                      "--model", "hex_4x5_home", "--device", "scripted:palpate", "--duration", "3", "--no-realtime",
                      "--cache-dir", s->dir + "/cache"},
                     s->dir + "/agent.log");
  if (agent.Wait(std::chrono::seconds(60)) != 0) return void(s->error = "agent: " + agent.Log());
  // The session ends; its recording downloads.
  const bool ended = Eventually([&] {
    const HttpReply r = Get(s->server->port(), "/api/sessions", observer);
    if (r.status != 200) return false;
    const json list = json::parse(r.body)["sessions"];
    if (list.empty() || list[0]["state"] != "ended") return false;
    s->id = list[0]["id"];
    return true;
  });
  if (!ended) return void(s->error = "the session did not end: " + s->server->Log());
  const HttpReply rec = Get(s->server->port(), "/api/sessions/" + s->id + "/recording.mcap", observer);
  if (rec.status != 200) return void(s->error = "recording download: HTTP " + std::to_string(rec.status));
  s->recording = s->dir + "/session.mcap";
  std::ofstream(s->recording, std::ios::binary) << rec.body;
  // The peak of |force| over the device batches, at its log time.
  RecordingReader reader;
  RecordingReaderOptions options;
  options.mesh = options.events = options.annotations = false;
  std::string error;
  if (!reader.Open(s->recording, options, &error)) return void(s->error = error);
  s->duration_s = (reader.end_ns() - reader.start_ns()) * 1e-9;
  RecordedMessage m;
  bool touched = false;
  while (reader.Next(&m, &error)) {
    // Before the first contact: the last batch none of whose ticks touched.
    bool contact = false;
    for (const v1::DeviceSample& d : m.envelope.device_samples().samples()) contact = contact || d.contact();
    touched = touched || contact;
    if (!touched && m.envelope.device_samples().samples_size() > 0)
      s->before_contact_t_s = (m.log_time_ns - reader.start_ns()) * 1e-9;
    for (const v1::DeviceSample& d : m.envelope.device_samples().samples()) {
      const double f = std::hypot(d.force().x(), d.force().y(), d.force().z());
      if (f > s->peak_force) {
        s->peak_force = f;
        s->peak_force_t_s = (m.log_time_ns - reader.start_ns()) * 1e-9;
        s->peak_tool_pos[0] = d.tool_pos().x(), s->peak_tool_pos[1] = d.tool_pos().y();
        s->peak_tool_pos[2] = d.tool_pos().z();
      }
    }
  }
  if (!error.empty()) s->error = error;
}

}  // namespace

RecordedSession& Session() {
  // Destroyed at exit, which stops the server.
  static RecordedSession session;
  static const bool made = (Make(&session), true);
  (void)made;
  return session;
}

}  // namespace idms::test
