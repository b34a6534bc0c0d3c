// idms-sim fit --recording on a real session recording (issue 34): the real idms-agent palpates
// hex_4x5_home through the real idms-server, which records the session; the recording, downloaded
// as a viewer would, fits back to the model it was made on (the scene's tool and step replayed, so
// every factor is 1), and fitting it to another model is refused with the reason; and the same
// through the server's POST /api/sessions/{id}/fit, whose fitted model is the library's next
// version with the fit's report in its metadata.
#include <gtest/gtest.h>

#include <csignal>
#include <cstdio>
#include <functional>
#include <string>

#include "idms/protocol/recording.h"
#include "idms/sim/model_io.h"
#include "server_process.h"
#include "session_checks.h"

namespace idms::test {
namespace {

using std::chrono::seconds;

// The fits at the sessions' priority: beside the other tests a lower one waits for minutes.
const std::vector<std::string> kFitArgs = {"--fit-nice", "0"};

// A copy of a recording with its metadata, every message kept but the /device batches `edit`
// returns false for (it may change the ones it keeps).
void Rewrite(const std::string& from, const std::string& to, const std::function<bool(int, v1::DeviceSamples*)>& edit) {
  RecordingReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(from, {}, &error)) << error;
  RecordingWriter writer;
  RecordingWriterOptions options;
  options.session = reader.session();
  ASSERT_TRUE(writer.Open(to, options, &error)) << error;
  RecordedMessage m;
  int batch = 0;
  while (reader.Next(&m, &error)) {
    if (m.envelope.has_device_samples() && !edit(batch++, m.envelope.mutable_device_samples())) continue;
    ASSERT_TRUE(writer.Write(m.envelope, m.log_time_ns, m.publish_time_ns, &error)) << error;
  }
  ASSERT_TRUE(error.empty()) << error;
  ASSERT_TRUE(writer.Close(&error)) << error;
}

// The real agent runs `device` on library model `model` for `duration` seconds through `server`;
// the session's id once it has ended ("" with a test failure otherwise).
std::string RecordSession(ServerProcess& server, const std::string& dir, const std::string& model,
                          const std::string& device, const std::string& duration) {
  const std::string observer = server.Token("observer");
  ChildProcess agent(IDMS_AGENT_BIN,
                     {"--server", "ws://127.0.0.1:" + server.port_string(), "--token", server.Token("agent"), "--model",
                      model, "--cache-dir", dir + "/cache", "--device", device, "--duration", duration},
                     dir + "/agent.log");
  const std::string id = WaitForLiveSession(server.port(), observer);
  if (id.empty()) {
    ADD_FAILURE() << server.Log() << agent.Log();
    return "";
  }
  if (agent.Wait(seconds(120)) != 0) {
    ADD_FAILURE() << agent.Log();
    return "";
  }
  if (!Eventually([&] { return Sessions(server.port(), observer)[0]["state"] == "ended"; })) {
    ADD_FAILURE() << server.Log();
    return "";
  }
  return id;
}

TEST(FitRecording, ASessionRecordingFitsBackToItsModelAndAnotherModelIsRefused) {
  const std::string dir = TempDir("fit-recording");
  ServerProcess server(dir + "/data", kFitArgs);
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string observer = server.Token("observer");
  const std::string id = RecordSession(server, dir, "hex_4x5_home", "scripted:palpate", "5.5");
  ASSERT_FALSE(id.empty());
  const std::string rec = dir + "/palpate.mcap";
  ASSERT_TRUE(DownloadRecording(server.port(), id, observer, rec));

  const std::string models = std::string(IDMS_SOURCE_DIR) + "/models/";
  ASSERT_EQ(RunCommand({IDMS_SIM_BIN, "fit", "--model", models + "hex_4x5_home", "--recording", rec, "--params",
                        "home_k,tool_k", "--json"},
                       dir + "/fit.json"),
            0)
      << ReadText(dir + "/fit.json");
  const nlohmann::json fit = nlohmann::json::parse(ReadText(dir + "/fit.json"));
  EXPECT_GE(fit["samples"].get<int>(), 5400) << "the whole palpation, tick by tick";
  EXPECT_EQ(fit["rms_before"].get<double>(), 0.0) << "the replay gives the agent's forces to the bit";
  EXPECT_GT(fit["peak_force"].get<double>(), 1.0);
  for (const char* p : {"home_k", "tool_k"}) {
    EXPECT_NEAR(fit["params"][p]["scale"].get<double>(), 1.0, 1e-6) << p;
  }
  EXPECT_EQ(fit["params"]["tool_k"]["value"].get<double>(), 400.0 * fit["params"]["tool_k"]["scale"].get<double>())
      << "the scene's tool: the thesis's k = 400";

  // The same model typed in 20% too soft: the recording gives the factor back.
  Model soft;
  LoadError load_error;
  ASSERT_TRUE(LoadModel(models + "hex_4x5_home.fem", models + "hex_4x5_home.plg", {}, &soft, &load_error))
      << load_error.ToString();
  for (double& k : soft.elem_k) k *= 0.8;
  std::string error;
  ASSERT_TRUE(SaveModel(soft, dir + "/soft", &error)) << error;
  ASSERT_EQ(RunCommand({IDMS_SIM_BIN, "fit", "--model", dir + "/soft", "--recording", rec, "--params", "k", "--json"},
                       dir + "/soft.json"),
            0)
      << ReadText(dir + "/soft.json");
  const nlohmann::json soft_fit = nlohmann::json::parse(ReadText(dir + "/soft.json"));
  EXPECT_NEAR(soft_fit["params"]["k"]["scale"].get<double>(), 1.25, 1e-4) << soft_fit.dump();

  // Another model's surface: refused, and why.
  EXPECT_EQ(RunCommand({IDMS_SIM_BIN, "fit", "--model", models + "slab_40x40", "--recording", rec}, dir + "/other.log"),
            1);
  EXPECT_NE(ReadText(dir + "/other.log").find("palpate.mcap: its model has 22 surface vertices, the model given 1620"),
            std::string::npos)
      << ReadText(dir + "/other.log");
  // A recording that lost ticks, or whose force the passivity controller changed, is not the
  // tissue's: refused, and why.
  uint64_t lost[2] = {0, 0};  // the dropped batch's first and last tick
  Rewrite(rec, dir + "/gap.mcap", [&](int batch, v1::DeviceSamples* samples) {
    if (batch != 9) return true;
    lost[0] = samples->samples(0).tick(), lost[1] = samples->samples(samples->samples_size() - 1).tick();
    return false;
  });
  EXPECT_EQ(RunCommand({IDMS_SIM_BIN, "fit", "--model", models + "hex_4x5_home", "--recording", dir + "/gap.mcap"},
                       dir + "/gap.log"),
            1);
  EXPECT_NE(ReadText(dir + "/gap.log")
                .find("gap.mcap: ticks " + std::to_string(lost[0]) + " to " + std::to_string(lost[1]) +
                      " are missing (the session lost them)"),
            std::string::npos)
      << ReadText(dir + "/gap.log");
  Rewrite(rec, dir + "/passive.mcap", [](int batch, v1::DeviceSamples* samples) {
    if (batch == 50) samples->mutable_samples(3)->set_passivity_damping(0.5);
    return true;
  });
  EXPECT_EQ(RunCommand({IDMS_SIM_BIN, "fit", "--model", models + "hex_4x5_home", "--recording", dir + "/passive.mcap"},
                       dir + "/passive.log"),
            1);
  EXPECT_NE(ReadText(dir + "/passive.log").find("the passivity controller added damping on 1 ticks"), std::string::npos)
      << ReadText(dir + "/passive.log");

  // One source only, and the scene's tool is not overridden.
  EXPECT_EQ(RunCommand(
                {IDMS_SIM_BIN, "fit", "--model", models + "hex_4x5_home", "--recording", rec, "--tool", "sphere:k=500"},
                dir + "/tool.log"),
            1);
  EXPECT_NE(ReadText(dir + "/tool.log").find("the session's scene gives the tool and the step"), std::string::npos)
      << ReadText(dir + "/tool.log");
}

HttpReply Call(uint16_t port, const std::string& method, const std::string& target, const std::string& token,
               const std::string& body = "") {
  return Http(
      port,
      HttpCall{method, target, {{"Authorization", "Bearer " + token}, {"Content-Type", "application/json"}}, body});
}

// The fit job of session `id` once it has finished (done, failed or stopped); null on a timeout.
nlohmann::json FinishedFit(uint16_t port, const std::string& id, const std::string& token) {
  nlohmann::json job;
  Eventually(
      [&] {
        const HttpReply r = Get(port, "/api/sessions/" + id + "/fit", token);
        job = nlohmann::json::parse(r.body, nullptr, false);
        return r.status == 200 && job.is_object() && job["state"] != "queued" && job["state"] != "running";
      },
      seconds(120));
  return job;
}

// The pluck's tweezers: replayed closed where the recording held the atom, the session's forces
// come back to the bit, and the model fits back to itself.
TEST(FitRecording, APlucksRecordingIsReplayedWithItsGraspToTheBit) {
  const std::string dir = TempDir("fit-pluck");
  ServerProcess server(dir + "/data", kFitArgs);
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string id = RecordSession(server, dir, "hex_4x5_home", "scripted:pluck", "5");
  ASSERT_FALSE(id.empty());
  const std::string rec = dir + "/pluck.mcap";
  ASSERT_TRUE(DownloadRecording(server.port(), id, server.Token("observer"), rec));
  const std::string models = std::string(IDMS_SOURCE_DIR) + "/models/";
  ASSERT_EQ(RunCommand({IDMS_SIM_BIN, "fit", "--model", models + "hex_4x5_home", "--recording", rec, "--params",
                        "home_k", "--json"},
                       dir + "/fit.json"),
            0)
      << ReadText(dir + "/fit.json");
  const nlohmann::json fit = nlohmann::json::parse(ReadText(dir + "/fit.json"));
  EXPECT_GE(fit["samples"].get<int>(), 4900);
  EXPECT_EQ(fit["rms_before"].get<double>(), 0.0) << "the replay gives the agent's forces to the bit";
  EXPECT_NEAR(fit["params"]["home_k"]["scale"].get<double>(), 1.0, 1e-6);
}

TEST(FitEndpoint, AnAdminFitsASessionAndTheLibraryGetsTheNextVersionWithTheReport) {
  const std::string dir = TempDir("fit-endpoint");
  ServerProcess server(dir + "/data", kFitArgs);
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string admin = server.Token("admin"), observer = server.Token("observer");
  const std::string models = std::string(IDMS_SOURCE_DIR) + "/models/";
  // hex_4x5_home typed in 20% too soft, as a model of its own.
  Model soft;
  LoadError load_error;
  ASSERT_TRUE(LoadModel(models + "hex_4x5_home.fem", models + "hex_4x5_home.plg", {}, &soft, &load_error))
      << load_error.ToString();
  const std::vector<double> true_k = soft.elem_k;
  for (double& k : soft.elem_k) k *= 0.8;
  ASSERT_EQ(Call(server.port(), "PUT", "/api/models/hex_soft", admin,
                 JsonUpload(WriteFem(soft), WritePlg(soft), "typed in too soft"))
                .status,
            201);
  const nlohmann::json soft_v1 = nlohmann::json::parse(Get(server.port(), "/api/models/hex_soft", observer).body);

  ChildProcess agent(
      IDMS_AGENT_BIN,
      {"--server", "ws://127.0.0.1:" + server.port_string(), "--token", server.Token("agent"), "--model",
       "hex_4x5_home", "--cache-dir", dir + "/cache", "--device", "scripted:palpate", "--duration", "5.5"},
      dir + "/agent.log");
  const std::string id = WaitForLiveSession(server.port(), observer);
  ASSERT_FALSE(id.empty()) << server.Log() << agent.Log();
  const std::string fit = "/api/sessions/" + id + "/fit";
  // An observer may not; a live session's recording is not whole yet.
  EXPECT_EQ(Call(server.port(), "POST", fit, observer).status, 403);
  HttpReply r = Call(server.port(), "POST", fit, admin);
  EXPECT_EQ(r.status, 409) << r.body;
  EXPECT_NE(r.body.find("is live: fit it once it has ended"), std::string::npos) << r.body;
  ASSERT_EQ(agent.Wait(seconds(60)), 0) << agent.Log();
  ASSERT_TRUE(Eventually([&] { return Sessions(server.port(), observer)[0]["state"] == "ended"; })) << server.Log();

  // Bad requests say what is wrong; an unknown session is not found.
  r = Call(server.port(), "POST", fit, admin, R"({"params": "home_k,stiffness"})");
  EXPECT_EQ(r.status, 400);
  EXPECT_NE(r.body.find("params: "), std::string::npos) << r.body;
  r = Call(server.port(), "POST", fit, admin, R"({"regions": ["lump=cube:1,2"]})");
  EXPECT_EQ(r.status, 400);
  EXPECT_NE(r.body.find("regions: "), std::string::npos) << r.body;
  EXPECT_EQ(Call(server.port(), "POST", fit, admin, R"({"modell": "x"})").status, 400);
  EXPECT_EQ(Call(server.port(), "POST", "/api/sessions/nosuch/fit", admin).status, 404);
  EXPECT_EQ(Get(server.port(), fit, observer).status, 404) << "no fit asked for yet";

  // Fitted to the soft model: the factor that makes it the model the session ran.
  r = Call(server.port(), "POST", fit, admin, R"({"model": "hex_soft", "params": ["k"]})");
  ASSERT_EQ(r.status, 202) << r.body;
  EXPECT_EQ(r.headers["location"], fit);
  nlohmann::json job = FinishedFit(server.port(), id, observer);
  ASSERT_EQ(job["state"], "done") << job.dump() << server.Log();
  EXPECT_EQ(job["result"]["model"]["name"], "hex_soft");
  EXPECT_EQ(job["result"]["model"]["version"], 2);
  EXPECT_NEAR(job["result"]["params"][0]["scale"].get<double>(), 1.25, 1e-4) << job.dump();

  // The library: version 2 with the report, version 1 as it was.
  const nlohmann::json v2 = nlohmann::json::parse(Get(server.port(), "/api/models/hex_soft?version=2", observer).body);
  const nlohmann::json& report = v2["metadata"]["fit"];
  EXPECT_EQ(report["session"], id);
  EXPECT_EQ(report["from"]["version"], 1);
  EXPECT_EQ(report["params"][0]["name"], "k");
  EXPECT_NEAR(report["params"][0]["scale"].get<double>(), 1.25, 1e-4);
  EXPECT_LT(report["rms_after"].get<double>(), 1e-3 * report["rms_before"].get<double>()) << report.dump();
  const size_t points = report["curve"]["t"].size();
  EXPECT_GT(points, 100u);
  EXPECT_LE(points, 500u);
  EXPECT_EQ(report["curve"]["measured"].size(), points);
  EXPECT_EQ(report["curve"]["fitted"].size(), points);
  EXPECT_NE(v2["description"].get<std::string>().find("fitted to session " + id), std::string::npos);
  EXPECT_EQ(v2["versions"][1]["fitted_to_session"], id);
  EXPECT_FALSE(v2["versions"][0].contains("fitted_to_session"));
  const nlohmann::json v1 = nlohmann::json::parse(Get(server.port(), "/api/models/hex_soft?version=1", observer).body);
  EXPECT_EQ(v1["fem_sha256"], soft_v1["fem_sha256"]);
  EXPECT_FALSE(v1.contains("metadata"));
  // The fitted file itself: the stiffness the session ran, to the fit's precision.
  const HttpReply fem = Get(server.port(), "/api/models/hex_soft/fem?version=2", observer);
  ASSERT_EQ(fem.status, 200);
  Model fitted;
  ASSERT_TRUE(ParseFem(fem.body, "hex_soft.fem", &fitted, &load_error)) << load_error.ToString();
  ASSERT_EQ(fitted.elem_k.size(), true_k.size());
  for (size_t e = 0; e < true_k.size(); ++e) ASSERT_NEAR(fitted.elem_k[e], true_k[e], 1e-4 * true_k[e]) << e;

  // With no model named: the one the session ran (hex_4x5_home v1), fitted back to itself.
  ASSERT_EQ(Call(server.port(), "POST", fit, admin, R"({"params": "home_k"})").status, 202);
  job = FinishedFit(server.port(), id, observer);
  ASSERT_EQ(job["state"], "done") << job.dump() << server.Log();
  EXPECT_EQ(job["result"]["model"]["name"], "hex_4x5_home");
  EXPECT_EQ(job["result"]["model"]["version"], 2);
  EXPECT_NEAR(job["result"]["params"][0]["scale"].get<double>(), 1.0, 1e-6);
  // Another model's surface: the job fails with the reason, and the library is as it was.
  ASSERT_EQ(Call(server.port(), "POST", fit, admin, R"({"model": "slab_40x40"})").status, 202);
  job = FinishedFit(server.port(), id, observer);
  EXPECT_EQ(job["state"], "failed");
  EXPECT_NE(job["error"].get<std::string>().find("session " + id + "'s recording: its model has 22 surface vertices"),
            std::string::npos)
      << job.dump();
  EXPECT_EQ(nlohmann::json::parse(Get(server.port(), "/api/models/slab_40x40", observer).body)["latest_version"], 1);
  // The gauges are back to nothing; the counters say how the fits ended.
  EXPECT_EQ(MetricValue(server.port(), observer, "idms_fit_jobs{state=\"running\"}"), 0);
  EXPECT_EQ(MetricValue(server.port(), observer, "idms_fit_jobs{state=\"queued\"}"), 0);
  EXPECT_EQ(MetricValue(server.port(), observer, "idms_fits_total{result=\"done\"}"), 2);
  EXPECT_EQ(MetricValue(server.port(), observer, "idms_fits_total{result=\"failed\"}"), 1);
}

// A fit running when the server stops ends at its solver's next iteration: the server exits at
// once and cleanly, and the library is as it was (no half-stored version).
TEST(FitEndpoint, AFitRunningWhenTheServerStopsEndsThereAndTheServerExits) {
  const std::string dir = TempDir("fit-stop");
  std::string observer, admin, id;
  {
    ServerProcess server(dir + "/data", kFitArgs);
    ASSERT_TRUE(server.ready()) << server.Log();
    observer = server.Token("observer"), admin = server.Token("admin");
    // The slab typed in 20% too soft: the fit starts away from its answer (the session's own model
    // is at it from the first evaluation, and a solve that has nothing to do ends at once).
    Model soft;
    LoadError load_error;
    const std::string models = std::string(IDMS_SOURCE_DIR) + "/models/";
    ASSERT_TRUE(LoadModel(models + "slab_40x40.fem", models + "slab_40x40.plg", {}, &soft, &load_error))
        << load_error.ToString();
    for (double& k : soft.elem_k) k *= 0.8;
    ASSERT_EQ(Call(server.port(), "PUT", "/api/models/slab_soft", admin,
                   JsonUpload(WriteFem(soft), WritePlg(soft), "typed in too soft"))
                  .status,
              201);
    id = RecordSession(server, dir, "slab_40x40", "scripted:palpate", "3");
    ASSERT_FALSE(id.empty());
    ASSERT_EQ(
        Call(
            server.port(), "POST", "/api/sessions/" + id + "/fit", admin,
            R"({"model": "slab_soft", "params": "home_k,home_b,surface_k,surface_b,tool_k", "regions": ["a=box:0,0,-99,20,17,99",
                       "b=box:20,0,-99,40,17,99", "c=box:0,17,-99,20,34,99"]})")
            .status,
        202);
    nlohmann::json job;
    ASSERT_TRUE(Eventually(
        [&] {
          job = nlohmann::json::parse(Get(server.port(), "/api/sessions/" + id + "/fit", observer).body);
          return job["state"] == "running" && job.contains("progress") && job["progress"]["replays"].get<int>() > 0;
        },
        seconds(60)))
        << job.dump();
    const auto t0 = std::chrono::steady_clock::now();
    server.process().Signal(SIGTERM);
    ASSERT_EQ(server.process().Wait(seconds(60)), 0) << server.Log();
    const double stop_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("the server stopped %.2f s after SIGTERM, %d replays into the fit\n", stop_s,
                job["progress"]["replays"].get<int>());
    // 17 unknowns (4 groups in 4 parts, and the tool): hundreds of replays from the end.
    EXPECT_NE(server.Log().find("the server stopped"), std::string::npos) << server.Log();
    EXPECT_EQ(server.Log().find("fit done"), std::string::npos) << server.Log();
  }
  ServerProcess again(dir + "/data", kFitArgs);
  ASSERT_TRUE(again.ready()) << again.Log();
  EXPECT_EQ(nlohmann::json::parse(Get(again.port(), "/api/models/slab_soft", observer).body)["latest_version"], 1);
  EXPECT_EQ(Get(again.port(), "/api/sessions/" + id + "/fit", observer).status, 404) << "jobs are the process's";
}

// A scan of the tumour slab, mapped through the server against the plain slab (what the tissue was
// believed to be): the job finds the lump where the tumour is, and the plain slab's next version
// carries the map (49 presses) and the lump in its metadata.
TEST(FitScanEndpoint, AScanIsMappedAndTheLumpIsFoundWhereTheTumourIs) {
  const std::string dir = TempDir("fit-map");
  ServerProcess server(dir + "/data", kFitArgs);
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string admin = server.Token("admin"), observer = server.Token("observer");
  const std::string id = RecordSession(server, dir, "slab_40x40_tumour", "scripted:scan", "50");
  ASSERT_FALSE(id.empty());
  const std::string fit = "/api/sessions/" + id + "/fit";
  HttpReply r = Call(server.port(), "POST", fit, admin, R"({"map": true, "params": "k"})");
  EXPECT_EQ(r.status, 400);
  EXPECT_NE(r.body.find("give no params or regions"), std::string::npos) << r.body;
  ASSERT_EQ(Call(server.port(), "POST", fit, admin, R"({"model": "slab_40x40", "map": true})").status, 202);
  const nlohmann::json job = FinishedFit(server.port(), id, observer);
  ASSERT_EQ(job["state"], "done") << job.dump() << server.Log();
  const nlohmann::json& lump = job["result"]["lump"];
  ASSERT_TRUE(lump["found"].get<bool>()) << job.dump();
  // The tumour: a sphere of radius 4 at (20, 17, -0.4), k x 8; the slab's elements are 1 apart.
  EXPECT_NEAR(lump["x"].get<double>(), 20.0, 1.0) << job.dump();
  EXPECT_NEAR(lump["y"].get<double>(), 17.0, 1.0) << job.dump();
  EXPECT_NEAR(lump["ratio"].get<double>(), 8.0, 0.8) << job.dump();
  const nlohmann::json v2 =
      nlohmann::json::parse(Get(server.port(), "/api/models/slab_40x40?version=2", observer).body);
  const nlohmann::json& report = v2["metadata"]["fit"];
  EXPECT_EQ(report["kind"], "map");
  EXPECT_EQ(report["session"], id);
  EXPECT_EQ(report["map"]["points"].size(), 49u);
  EXPECT_EQ(report["map"]["lump"]["x"], lump["x"]);
  EXPECT_NE(v2["description"].get<std::string>().find("stiffness map of session " + id), std::string::npos);
}

}  // namespace
}  // namespace idms::test
