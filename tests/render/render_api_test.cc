// The server's screenshot and thumbnail endpoints with the real idms-server: tokens and roles,
// bad parameters (400 with a reason), the cache (hit, ETag, 304), and a burst beyond the render
// queue answered 503 + Retry-After, never anything else.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <thread>

#include "idms/render/png.h"
#include "recording_fixture.h"

namespace idms::test {
namespace {

using json = nlohmann::json;

class RenderApiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_EQ(Session().error, "");
    port_ = Session().server->port();
    observer_ = Session().server->Token("observer");
  }
  HttpReply Shot(const std::string& query, const std::string& token) {
    return Get(port_, "/api/sessions/" + Session().id + "/screenshot.png" + query, token);
  }
  uint16_t port_ = 0;
  std::string observer_;
};

void ExpectPng(const HttpReply& r, int width, int height) {
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.headers.at("content-type"), "image/png");
  render::Image image;
  std::string error;
  ASSERT_TRUE(render::DecodePng(r.body, &image, &error)) << error;
  EXPECT_EQ(image.width, width);
  EXPECT_EQ(image.height, height);
}

void ExpectBadRequest(const HttpReply& r, const std::string& reason) {
  EXPECT_EQ(r.status, 400) << r.body;
  const json body = json::parse(r.body, nullptr, false);
  ASSERT_TRUE(body.is_object()) << r.body;
  EXPECT_NE(body.value("error", "").find(reason), std::string::npos) << r.body;
}

TEST_F(RenderApiTest, ScreenshotWithTokensSizesAndTheCache) {
  const std::string t = "?t=" + std::to_string(Session().peak_force_t_s);
  // An observer's token: a PNG of the asked size; the default size is 1280x720.
  const HttpReply first = Shot(t + "&size=640x360", observer_);
  ExpectPng(first, 640, 360);
  EXPECT_NE(first.headers.at("server-timing").find("miss"), std::string::npos);
  ExpectPng(Shot("?t=0.5", observer_), 1280, 720);
  ExpectPng(Shot(t + "&size=320x200&wireframe=1&tool=0&force=0", Session().server->Token("admin")), 320, 200);
  // The same request again: the same bytes from the cache, with the same ETag; 304 with it.
  const HttpReply again = Shot(t + "&size=640x360", observer_);
  ASSERT_EQ(again.status, 200);
  EXPECT_EQ(again.body, first.body);
  EXPECT_EQ(again.headers.at("etag"), first.headers.at("etag"));
  EXPECT_NE(again.headers.at("server-timing").find("hit"), std::string::npos);
  const HttpReply not_modified =
      Http(port_, HttpCall{"GET",
                           "/api/sessions/" + Session().id + "/screenshot.png" + t + "&size=640x360",
                           {{"Authorization", "Bearer " + observer_}, {"If-None-Match", first.headers.at("etag")}},
                           ""});
  EXPECT_EQ(not_modified.status, 304);
  // Another time is another image.
  const HttpReply other = Shot("?t=0&size=640x360", observer_);
  ASSERT_EQ(other.status, 200);
  EXPECT_NE(other.body, first.body);
  EXPECT_NE(other.headers.at("etag"), first.headers.at("etag"));
  // Without a token, or with a wrong one: 401.
  EXPECT_EQ(Shot(t, "").status, 401);
  EXPECT_EQ(Shot(t, "not-a-token-at-all-xxxxxxxx").status, 401);
  // No such session: 404.
  EXPECT_EQ(Get(port_, "/api/sessions/nope/screenshot.png", observer_).status, 404);
}

TEST_F(RenderApiTest, BadParametersAre400WithAReason) {
  ExpectBadRequest(Shot("?size=8000x8000", observer_), "out of range");
  ExpectBadRequest(Shot("?size=big", observer_), "WIDTHxHEIGHT");
  ExpectBadRequest(Shot("?t=" + std::to_string(Session().duration_s + 60), observer_), "outside the recording");
  ExpectBadRequest(Shot("?t=-1", observer_), "t:");
  ExpectBadRequest(Shot("?t=abc", observer_), "t:");
  ExpectBadRequest(Shot("?wireframe=yes", observer_), "wireframe");
  ExpectBadRequest(Shot("?zoom=2", observer_), "unknown parameter");
  ExpectBadRequest(Get(port_, "/api/models/hex_4x5_home/thumbnail.png?version=x", observer_), "version");
  ExpectBadRequest(Get(port_, "/api/models/hex_4x5_home/thumbnail.png?size=1x1", observer_), "size");
}

TEST_F(RenderApiTest, ModelThumbnailsAndTheListing) {
  const HttpReply thumb = Get(port_, "/api/models/hex_4x5_home/thumbnail.png", observer_);
  ExpectPng(thumb, 320, 240);
  EXPECT_EQ(thumb.headers.at("cache-control"), "private, no-cache");
  const HttpReply v1 = Get(port_, "/api/models/hex_4x5_home/thumbnail.png?version=1&size=200x150", observer_);
  ExpectPng(v1, 200, 150);
  EXPECT_NE(v1.headers.at("cache-control").find("immutable"), std::string::npos);
  EXPECT_EQ(Get(port_, "/api/models/hex_4x5_home/thumbnail.png?version=99", observer_).status, 404);
  EXPECT_EQ(Get(port_, "/api/models/no_such_model/thumbnail.png", observer_).status, 404);
  EXPECT_EQ(Get(port_, "/api/models/hex_4x5_home/thumbnail.png", "").status, 401);
  // Other models look different.
  const HttpReply cap = Get(port_, "/api/models/sphere_cap/thumbnail.png", observer_);
  ASSERT_EQ(cap.status, 200);
  EXPECT_NE(cap.body, thumb.body);
  // The listing names each model's thumbnail, and the URL serves it.
  const json models = json::parse(Get(port_, "/api/models", observer_).body)["models"];
  ASSERT_FALSE(models.empty());
  for (const json& m : models) {
    const std::string url = m.value("thumbnail", "");
    EXPECT_EQ(url, "/api/models/" + m["name"].get<std::string>() +
                       "/thumbnail.png?version=" + std::to_string(m["latest_version"].get<int>()));
  }
  EXPECT_EQ(Get(port_, models[0]["thumbnail"].get<std::string>(), observer_).status, 200);
  // The model's files are still served at their own route.
  EXPECT_EQ(Get(port_, "/api/models/hex_4x5_home/plg", observer_).status, 200);
}

TEST_F(RenderApiTest, ABurstBeyondTheRenderQueueGets503AndRetryAfter) {
  // Distinct large images (no cache hits) at once from more clients than the server has render
  // slots; tried a few times, since a fast machine may finish some before the others arrive.
  int busy = 0, ok = 0, round = 0;
  for (; round < 4 && busy == 0; ++round) {
    constexpr int kClients = 12;
    std::vector<HttpReply> replies(kClients);
    std::vector<std::thread> clients;
    for (int i = 0; i < kClients; ++i) {
      clients.emplace_back(
          [&, i] { replies[i] = Shot("?t=" + std::to_string(0.1 * i + 0.01 * round) + "&size=1920x1080", observer_); });
    }
    for (std::thread& c : clients) c.join();
    for (const HttpReply& r : replies) {
      ASSERT_TRUE(r.status == 200 || r.status == 503) << r.status << " " << r.body;
      if (r.status == 503) {
        ++busy;
        EXPECT_EQ(r.headers.at("retry-after"), "1");
        EXPECT_NE(r.body.find("busy"), std::string::npos);
      } else {
        ++ok;
      }
    }
  }
  EXPECT_GT(busy, 0) << "no 503 in " << round << " bursts";
  EXPECT_GT(ok, 0);
  // /metrics counts them.
  const std::string metrics = Get(port_, "/metrics", observer_).body;
  EXPECT_NE(metrics.find("idms_render_busy_total "), std::string::npos) << metrics;
  EXPECT_EQ(metrics.find("idms_render_busy_total 0\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("idms_live_sessions "), std::string::npos) << "the sessions' lines stay";
  // Afterwards the server renders again.
  EXPECT_EQ(Shot("?t=0.2&size=320x200", observer_).status, 200);
}

// idms-render itself: a recording at a time and every 0.5 s of it, and a live session as a viewer.
TEST_F(RenderApiTest, TheCommandLineRendersRecordingsAndALiveSession) {
  const std::string dir = TempDir("render-cli");
  ChildProcess at(IDMS_RENDER_BIN,
                  {"--recording", Session().recording, "--at", "1.0", "--out", dir + "/at.png", "--size", "400x300",
                   "--show-tool", "--show-force"},
                  dir + "/at.log");
  ASSERT_EQ(at.Wait(std::chrono::seconds(60)), 0) << at.Log();
  render::Image image;
  std::string error;
  ASSERT_TRUE(render::DecodePng(ReadText(dir + "/at.png"), &image, &error)) << error;
  EXPECT_EQ(image.width, 400);
  ChildProcess every(
      IDMS_RENDER_BIN,
      {"--recording", Session().recording, "--every", "0.5", "--out", dir + "/frames", "--size", "320x240"},
      dir + "/every.log");
  ASSERT_EQ(every.Wait(std::chrono::seconds(60)), 0) << every.Log();
  const int frames = static_cast<int>(Session().duration_s / 0.5) + 1;
  for (int i = 0; i < frames; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "/frame_%06d.png", i);
    EXPECT_TRUE(render::DecodePng(ReadText(dir + "/frames" + name), &image, &error)) << name << ": " << error;
  }
  // A time outside the recording: exit 2 with the reason.
  ChildProcess outside(IDMS_RENDER_BIN, {"--recording", Session().recording, "--at", "999", "--out", dir + "/x.png"},
                       dir + "/outside.log");
  EXPECT_EQ(outside.Wait(std::chrono::seconds(60)), 2);
  EXPECT_NE(outside.Log().find("outside the recording"), std::string::npos) << outside.Log();
  // Live: an agent publishes for 3 s; idms-render joins as a viewer and draws what arrives.
  ChildProcess agent(IDMS_AGENT_BIN,
                     {"--server", "ws://127.0.0.1:" + Session().server->port_string(), "--token",
                      Session().server->Token("agent"), "--model", "hex_4x5_home", "--device", "scripted:palpate",
                      "--duration", "3", "--no-realtime", "--cache-dir", dir + "/cache"},
                     dir + "/agent.log");
  std::string live_id;
  ASSERT_TRUE(Eventually([&] {
    const json list = json::parse(Get(port_, "/api/sessions", observer_).body);
    for (const json& s : list["sessions"]) {
      if (s["state"] == "live") live_id = s["id"];
    }
    return !live_id.empty();
  }));
  // The server's screenshot of the live session: from its recording so far.
  ASSERT_TRUE(Eventually(
      [&] { return Get(port_, "/api/sessions/" + live_id + "/screenshot.png?size=320x240", observer_).status == 200; },
      std::chrono::seconds(5)));
  ChildProcess live(IDMS_RENDER_BIN,
                    {"--server", "http://127.0.0.1:" + Session().server->port_string(), "--session", live_id, "--token",
                     observer_, "--out", dir + "/live.png", "--show-tool"},
                    dir + "/live.log");
  ASSERT_EQ(live.Wait(std::chrono::seconds(30)), 0) << live.Log();
  ASSERT_TRUE(render::DecodePng(ReadText(dir + "/live.png"), &image, &error)) << error;
  EXPECT_EQ(image.width, 1280);
  ChildProcess refused(IDMS_RENDER_BIN,
                       {"--server", "http://127.0.0.1:" + Session().server->port_string(), "--session", live_id,
                        "--token", "wrong-token-xxxxxxxxxxxx", "--out", dir + "/refused.png"},
                       dir + "/refused.log");
  EXPECT_EQ(refused.Wait(std::chrono::seconds(30)), 2);
  EXPECT_NE(refused.Log().find("HTTP 401"), std::string::npos) << refused.Log();
  EXPECT_EQ(agent.Wait(std::chrono::seconds(60)), 0) << agent.Log();
}

}  // namespace
}  // namespace idms::test
