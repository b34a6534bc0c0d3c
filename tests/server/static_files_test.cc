// The web viewer's static files without sockets: page URLs get index.html, assets their type and
// ETag (304 on a match), nothing outside the build directory, API routes first.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "child_process.h"
#include "idms/server/api.h"

namespace idms::server {
namespace {

class StaticFilesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = test::TempDir("static-files");
    std::filesystem::create_directories(root_ + "/assets");
    Write("index.html", "<!doctype html><title>idms</title>");
    Write("assets/app.js", "console.log(1);");
    Write("assets/app.css", "body{}");
    Write("secret", "not served");
    options_.web_root = root_;
    ctx_.options = &options_;
    ctx_.logins = &logins_;
    ctx_.tokens = [] { return std::make_shared<const TokenTable>(); };
  }

  void Write(const std::string& name, const std::string& text) { std::ofstream(root_ + "/" + name) << text; }

  ApiResponse Get(const std::string& target, const std::string& if_none_match = "") {
    ApiRequest req;
    req.message = http::request<http::string_body>(http::verb::get, target, 11);
    req.message.set(http::field::host, "idms.local:8740");
    if (!if_none_match.empty()) req.message.set(http::field::if_none_match, if_none_match);
    Admission a = Admit(ctx_, routes_, req);
    if (a.error) return *a.error;
    HandlerResponse reply = a.route->handler(ctx_, req);
    if (auto* in_memory = std::get_if<ApiResponse>(&reply)) return std::move(*in_memory);
    // A streamed file: read its range as the connection would, into a string body.
    FileResponse& streamed = std::get<FileResponse>(reply);
    ApiResponse res{streamed.result(), streamed.version()};
    for (const auto& field : streamed) res.set(field.name_string(), field.value());
    res.body().resize(streamed.body().length);
    boost::beast::error_code ec;
    streamed.body().file.seek(streamed.body().offset, ec);
    const size_t got = streamed.body().file.read(res.body().data(), res.body().size(), ec);
    EXPECT_FALSE(ec);
    EXPECT_EQ(got, res.body().size());
    return res;
  }

  std::string root_;
  ServerOptions options_;
  MemoryLoginSessions logins_{std::chrono::seconds(3600)};
  ApiContext ctx_;
  std::vector<Route> routes_ = MakeRoutes();
};

TEST_F(StaticFilesTest, PageUrlsServeIndexWithoutAToken) {
  for (const char* path : {"/", "/login", "/sessions", "/session/abc", "/replay/abc?t=1.5", "/models", "/models/hex"}) {
    const ApiResponse r = Get(path);
    EXPECT_EQ(r.result_int(), 200) << path;
    EXPECT_EQ(r[http::field::content_type], "text/html; charset=utf-8") << path;
    EXPECT_EQ(r.body(), "<!doctype html><title>idms</title>") << path;
  }
  // API routes keep precedence and their auth; unknown paths stay 404.
  EXPECT_EQ(Get("/api/models").result_int(), 401);
  EXPECT_EQ(Get("/session").result_int(), 404);
  EXPECT_EQ(Get("/models/a/b").result_int(), 404);
}

// Issue 28: a browser sent to an unknown URL got raw JSON; it gets a page with the way back now,
// while API clients keep the JSON error.
TEST_F(StaticFilesTest, AnUnknownPageIsAPageForABrowserAndJsonForTheApi) {
  const auto get = [&](const std::string& target, const char* accept) {
    ApiRequest req;
    req.message = http::request<http::string_body>(http::verb::get, target, 11);
    req.message.set(http::field::host, "idms.local:8740");
    if (accept != nullptr) req.message.set(http::field::accept, accept);
    Admission a = Admit(ctx_, routes_, req);
    EXPECT_TRUE(a.error) << target;
    return a.error ? *a.error : ApiResponse{};
  };
  const char* browser = "text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8";
  const ApiResponse page = get("/no/such/%3Cpage%3E", browser);
  EXPECT_EQ(page.result_int(), 404);
  EXPECT_EQ(page[http::field::content_type], "text/html; charset=utf-8");
  EXPECT_NE(page.body().find("<code>/no/such/&lt;page&gt;</code>"), std::string::npos) << page.body();
  EXPECT_NE(page.body().find("<a href=\"/\">"), std::string::npos);
  for (const auto& [target, accept] :
       {std::pair{"/no/such/page", static_cast<const char*>(nullptr)}, std::pair{"/api/nothing", browser}}) {
    const ApiResponse json = get(target, accept);
    EXPECT_EQ(json.result_int(), 404) << target;
    EXPECT_EQ(json[http::field::content_type], "application/json") << target;
  }
}

TEST_F(StaticFilesTest, AssetsHaveTypesAndRevalidate) {
  ApiResponse js = Get("/assets/app.js");
  ASSERT_EQ(js.result_int(), 200);
  EXPECT_EQ(js[http::field::content_type], "text/javascript; charset=utf-8");
  EXPECT_EQ(js[http::field::cache_control], "no-cache");
  EXPECT_EQ(js.body(), "console.log(1);");
  const std::string etag(js[http::field::etag]);
  ASSERT_FALSE(etag.empty());
  const ApiResponse again = Get("/assets/app.js", etag);
  EXPECT_EQ(again.result_int(), 304);
  EXPECT_TRUE(again.body().empty());
  EXPECT_EQ(Get("/assets/app.js", "\"other\"").result_int(), 200);
  EXPECT_EQ(Get("/assets/app.css")[http::field::content_type], "text/css; charset=utf-8");
  // A changed file gets a new ETag.
  Write("assets/app.js", "console.log(2); // longer");
  EXPECT_NE(Get("/assets/app.js")[http::field::etag], etag);
}

TEST_F(StaticFilesTest, NothingOutsideTheBuild) {
  EXPECT_EQ(Get("/assets/missing.js").result_int(), 404);
  EXPECT_EQ(Get("/assets/.hidden").result_int(), 404);
  EXPECT_NE(Get("/assets/%2e%2e%2fsecret").result_int(), 200);
  EXPECT_NE(Get("/assets/..%2fsecret").result_int(), 200);
  EXPECT_EQ(Get("/secret").result_int(), 404);
}

TEST_F(StaticFilesTest, AMissingBuildSaysWhatToDo) {
  options_.web_root = root_ + "/nowhere";
  const ApiResponse r = Get("/sessions");
  EXPECT_EQ(r.result_int(), 503);
  EXPECT_NE(r.body().find("scripts/build.sh"), std::string::npos) << r.body();
  options_.web_root.clear();
  EXPECT_EQ(Get("/").result_int(), 503);
}

}  // namespace
}  // namespace idms::server
