// The API without sockets: admission (routes, 401/403/404/405/413/415, Origin) and the library's
// handlers, with the library checked unchanged after every refused upload.
#include "idms/server/api.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "child_process.h"

namespace idms::server {
namespace {

using json = nlohmann::json;

const std::string kModels = std::string(IDMS_SOURCE_DIR) + "/models/";
const std::string kAdmin = "admin-token-aaaaaaaaaaaa", kAgent = "agent-token-bbbbbbbbbbbb",
                  kObserver = "observer-token-cccccccccc";

class ApiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string error;
    ASSERT_TRUE(
        OpenStorage(test::TempDir(::testing::UnitTest::GetInstance()->current_test_info()->name()), &storage_, &error))
        << error;
    library_ = std::make_unique<Library>(storage_.blobs.get(), storage_.models.get());
    auto table = std::make_shared<TokenTable>();
    ASSERT_TRUE(TokenTable::Parse("admin " + kAdmin + "\nagent " + kAgent + "\nobserver " + kObserver + "\n", "t",
                                  table.get(), &error));
    tokens_ = table;
    options_.allowed_origins = {"https://lab.example"};
    ctx_.options = &options_;
    ctx_.library = library_.get();
    ctx_.logins = &logins_;
    ctx_.metrics = &metrics_;
    ctx_.tokens = [this] { return tokens_; };
    ctx_.publish_library_event = [this](std::string e) { events_.push_back(std::move(e)); };
    fem_ = test::ReadText(kModels + "hex_4x5_home.fem");
    plg_ = test::ReadText(kModels + "hex_4x5_home.plg");
  }

  ApiResponse Call(http::verb method, const std::string& target, const std::string& token,
                   std::vector<std::pair<http::field, std::string>> headers = {}, const std::string& body = "") {
    ApiRequest req;
    req.message = http::request<http::string_body>(method, target, 11);
    req.message.set(http::field::host, "idms.local:8740");
    if (!token.empty()) req.message.set(http::field::authorization, "Bearer " + token);
    for (auto& [f, v] : headers) req.message.set(f, v);
    req.message.body() = body;
    req.message.prepare_payload();
    Admission a = Admit(ctx_, routes_, req);
    if (a.error) return *a.error;
    EXPECT_FALSE(a.route->websocket);
    // The library's routes answer from memory (only static files and recordings stream).
    return std::get<ApiResponse>(a.route->handler(ctx_, req));
  }

  ApiResponse Upload(const std::string& name, const std::string& fem, const std::string& plg,
                     const std::string& token = kAdmin) {
    return Call(http::verb::put, "/api/models/" + name, token, {{http::field::content_type, "application/json"}},
                json{{"fem", fem}, {"plg", plg}, {"description", "test"}}.dump());
  }

  // The whole library as the API lists it, for before/after comparisons.
  std::string Listing() { return Call(http::verb::get, "/api/models", kObserver).body(); }

  Storage storage_;
  std::unique_ptr<Library> library_;
  std::shared_ptr<const TokenTable> tokens_;
  ServerOptions options_;
  MemoryLoginSessions logins_{std::chrono::seconds(3600)};
  Metrics metrics_;
  ApiContext ctx_;
  std::vector<Route> routes_ = MakeRoutes();
  std::vector<std::string> events_;
  std::string fem_, plg_;
};

TEST_F(ApiTest, UploadListGetDownloadDelete) {
  ApiResponse r = Upload("hex", fem_, plg_);
  ASSERT_EQ(r.result_int(), 201) << r.body();
  EXPECT_EQ(r[http::field::location], "/api/models/hex?version=1");
  const json v1 = json::parse(r.body());
  EXPECT_EQ(v1["atoms"], 58);
  EXPECT_EQ(v1["elements"], 141);
  EXPECT_EQ(v1["triangles"], 28);
  EXPECT_EQ(v1["fem_sha256"], Sha256Hex(fem_));
  ASSERT_EQ(events_.size(), 1u);
  EXPECT_EQ(json::parse(events_[0])["event"], "model_added");
  // A second upload is version 2; version 1 stays downloadable.
  const std::string fem2 = fem_ + "\n";
  ASSERT_EQ(Upload("hex", fem2, plg_).result_int(), 201);
  const json meta = json::parse(Call(http::verb::get, "/api/models/hex", kAgent).body());
  EXPECT_EQ(meta["version"], 2);
  EXPECT_EQ(meta["latest_version"], 2);
  EXPECT_EQ(meta["versions"].size(), 2u);
  EXPECT_EQ(meta["fem_sha256"], Sha256Hex(fem2));
  EXPECT_EQ(json::parse(Call(http::verb::get, "/api/models/hex?version=1", kAgent).body())["fem_sha256"],
            Sha256Hex(fem_));
  ApiResponse f = Call(http::verb::get, "/api/models/hex/fem?version=1", kObserver);
  ASSERT_EQ(f.result_int(), 200);
  EXPECT_EQ(f.body(), fem_);
  EXPECT_EQ(f[http::field::etag], "\"" + Sha256Hex(fem_) + "\"");
  EXPECT_NE(std::string(f[http::field::cache_control]).find("immutable"), std::string::npos);
  EXPECT_EQ(std::string(Call(http::verb::get, "/api/models/hex/fem", kObserver)[http::field::cache_control]),
            "no-cache");
  // If-None-Match: 304, no body.
  ApiResponse nm = Call(http::verb::get, "/api/models/hex/fem?version=1", kObserver,
                        {{http::field::if_none_match, "\"" + Sha256Hex(fem_) + "\""}});
  EXPECT_EQ(nm.result_int(), 304);
  EXPECT_TRUE(nm.body().empty());
  // The obj is the surface: 22 vertices, 28 faces.
  const std::string obj = Call(http::verb::get, "/api/models/hex/obj", kObserver).body();
  size_t vs = 0, fs = 0;
  for (size_t p = 0; p < obj.size(); p = obj.find('\n', p) + 1) {
    vs += obj.compare(p, 2, "v ") == 0;
    fs += obj.compare(p, 2, "f ") == 0;
    if (obj.find('\n', p) == std::string::npos) break;
  }
  EXPECT_EQ(vs, 22u);
  EXPECT_EQ(fs, 28u);
  // Delete version 2, then the model.
  EXPECT_EQ(Call(http::verb::delete_, "/api/models/hex?version=2", kAdmin).result_int(), 200);
  EXPECT_EQ(json::parse(Call(http::verb::get, "/api/models/hex", kAgent).body())["version"], 1);
  EXPECT_EQ(Call(http::verb::get, "/api/models/hex?version=2", kAgent).result_int(), 404);
  EXPECT_EQ(Call(http::verb::delete_, "/api/models/hex", kAdmin).result_int(), 200);
  EXPECT_EQ(Call(http::verb::get, "/api/models/hex", kAgent).result_int(), 404);
  EXPECT_EQ(Call(http::verb::get, "/api/models/hex/fem", kAgent).result_int(), 404);
  EXPECT_EQ(Call(http::verb::delete_, "/api/models/hex", kAdmin).result_int(), 404);
  EXPECT_TRUE(storage_.blobs->List().empty());  // nothing names them any more
}

TEST_F(ApiTest, MultipartUploadAsCurlSendsIt) {
  const std::string body =
      "--B0undary\r\nContent-Disposition: form-data; name=\"fem\"; filename=\"h.fem\"\r\n\r\n" + fem_ +
      "\r\n--B0undary\r\nContent-Disposition: form-data; name=\"plg\"; filename=\"h.plg\"\r\n\r\n" + plg_ +
      "\r\n--B0undary\r\nContent-Disposition: form-data; name=\"description\"\r\n\r\nfrom a form\r\n--B0undary--\r\n";
  ApiResponse r = Call(http::verb::put, "/api/models/formed", kAdmin,
                       {{http::field::content_type, "multipart/form-data; boundary=B0undary"}}, body);
  ASSERT_EQ(r.result_int(), 201) << r.body();
  EXPECT_EQ(json::parse(r.body())["description"], "from a form");
  EXPECT_EQ(Call(http::verb::get, "/api/models/formed/plg", kObserver).body(), plg_);
}

TEST_F(ApiTest, BadUploadsAreRefusedAtTheirLineAndChangeNothing) {
  ASSERT_EQ(Upload("hex", fem_, plg_).result_int(), 201);
  const std::string before = Listing();
  const std::vector<std::string> blobs_before = storage_.blobs->List();
  // A malformed fem: the error names file, line and column.
  std::string bad_fem = fem_;
  bad_fem.replace(bad_fem.find("0.002 1001"), 10, "0.002 1009");
  ApiResponse r = Upload("hex", bad_fem, plg_);
  EXPECT_EQ(r.result_int(), 400);
  json e = json::parse(r.body());
  EXPECT_EQ(e["file"], "hex.fem");
  EXPECT_EQ(e["line"], 3);
  EXPECT_GT(e["column"].get<int>(), 0);
  EXPECT_NE(e["error"].get<std::string>().find("boundary condition"), std::string::npos);
  // A plg that is not this fem's surface.
  r = Upload("hex", fem_, test::ReadText(kModels + "sphere_cap.plg"));
  EXPECT_EQ(r.result_int(), 400);
  EXPECT_EQ(json::parse(r.body())["file"], "hex.plg");
  // Names.
  for (const std::string& name :
       std::vector<std::string>{".hidden", "a..b", std::string(65, 'n'), "sp%20ace", "semi;colon"}) {
    EXPECT_EQ(Upload(name, fem_, plg_).result_int(), 400) << name;
  }
  // Bodies and content types.
  EXPECT_EQ(
      Call(http::verb::put, "/api/models/hex", kAdmin, {{http::field::content_type, "application/json"}}).result_int(),
      400);
  EXPECT_EQ(
      Call(http::verb::put, "/api/models/hex", kAdmin, {{http::field::content_type, "text/plain"}}, "x").result_int(),
      415);
  EXPECT_EQ(Call(http::verb::put, "/api/models/hex", kAdmin, {}, "x").result_int(), 415);
  EXPECT_EQ(
      Call(http::verb::put, "/api/models/hex", kAdmin, {{http::field::content_type, "application/json"}}, "{\"fem\": 1")
          .result_int(),
      400);
  EXPECT_EQ(Call(http::verb::put, "/api/models/hex", kAdmin, {{http::field::content_type, "application/json"}},
                 "{\"fem\": \"x\"}")
                .result_int(),
            400);
  EXPECT_EQ(Call(http::verb::put, "/api/models/hex", kAdmin,
                 {{http::field::content_type, "multipart/form-data; boundary=zz"}}, "--zz\r\n\r\nx")
                .result_int(),
            400);
  // Over the upload limit: 413 from the announced length, before any body is read (the header
  // alone, as the connection admits it).
  options_.max_upload_bytes = 1000;
  EXPECT_EQ(Upload("hex", fem_, plg_).result_int(), 413);
  {
    ApiRequest header_only;
    header_only.message = http::request<http::string_body>(http::verb::put, "/api/models/hex", 11);
    header_only.message.set(http::field::host, "idms.local:8740");
    header_only.message.set(http::field::authorization, "Bearer " + kAdmin);
    header_only.message.set(http::field::content_type, "application/json");
    header_only.message.set(http::field::content_length, "5000");
    const Admission a = Admit(ctx_, routes_, header_only);
    ASSERT_TRUE(a.error);
    EXPECT_EQ(a.error->result_int(), 413);
    header_only.message.set(http::field::content_length, "900");
    EXPECT_FALSE(Admit(ctx_, routes_, header_only).error);
  }
  EXPECT_EQ(Listing(), before);
  EXPECT_EQ(storage_.blobs->List(), blobs_before);
  EXPECT_EQ(events_.size(), 1u);
}

TEST_F(ApiTest, TokensAndRoles) {
  // 401: none, unknown, malformed.
  ApiResponse r = Call(http::verb::get, "/api/models", "");
  EXPECT_EQ(r.result_int(), 401);
  EXPECT_TRUE(json::parse(r.body()).contains("error"));
  EXPECT_EQ(Call(http::verb::get, "/api/models", "wrong-token-123456789").result_int(), 401);
  EXPECT_EQ(Call(http::verb::get, "/api/models", "", {{http::field::authorization, "Basic eDp5"}}).result_int(), 401);
  // 403: observers and agents may not write.
  r = Upload("hex", fem_, plg_, kObserver);
  EXPECT_EQ(r.result_int(), 403);
  EXPECT_NE(json::parse(r.body())["error"].get<std::string>().find("observer"), std::string::npos);
  EXPECT_EQ(Upload("hex", fem_, plg_, kAgent).result_int(), 403);
  EXPECT_EQ(Call(http::verb::delete_, "/api/models/hex", kAgent).result_int(), 403);
  // Health needs no token; 404 and 405.
  EXPECT_EQ(Call(http::verb::get, "/api/health", "").result_int(), 200);
  EXPECT_EQ(Call(http::verb::get, "/api/nothing", kAdmin).result_int(), 404);
  r = Call(http::verb::post, "/api/models", kAdmin);
  EXPECT_EQ(r.result_int(), 405);
  EXPECT_EQ(r[http::field::allow], "GET");
  EXPECT_EQ(Call(http::verb::get, "/api/models/../tokens", kAdmin).result_int(), 400);
  // Bytes that are not UTF-8 in a path or a name: a JSON error, never an exception (found by http_fuzz).
  r = Call(http::verb::get, "/api/%FF%FE", kAdmin);
  EXPECT_EQ(r.result_int(), 404);
  EXPECT_NE(json::parse(r.body())["error"].get<std::string>().find("\xEF\xBF\xBD"), std::string::npos);
  EXPECT_EQ(Upload("bad%FFname", fem_, plg_).result_int(), 400);
}

TEST_F(ApiTest, LoginCookieWorksOnlyFromAllowedOriginsForWrites) {
  ApiResponse login = Call(http::verb::post, "/api/login", "", {{http::field::content_type, "application/json"}},
                           json{{"token", kAdmin}}.dump());
  ASSERT_EQ(login.result_int(), 200) << login.body();
  const std::string set_cookie(login[http::field::set_cookie]);
  EXPECT_NE(set_cookie.find("HttpOnly"), std::string::npos);
  EXPECT_NE(set_cookie.find("SameSite=Strict"), std::string::npos);
  EXPECT_EQ(set_cookie.find("Secure"), std::string::npos);  // plain HTTP here
  const std::string cookie = set_cookie.substr(0, set_cookie.find(';'));
  // Reads by cookie work from anywhere; writes only from the server's own or an allowed origin.
  EXPECT_EQ(Call(http::verb::get, "/api/models", "", {{http::field::cookie, cookie}}).result_int(), 200);
  auto upload = [&](const std::string& origin) {
    std::vector<std::pair<http::field, std::string>> h = {{http::field::cookie, cookie},
                                                          {http::field::content_type, "application/json"}};
    if (!origin.empty()) h.push_back({http::field::origin, origin});
    return Call(http::verb::put, "/api/models/hex", "", h, json{{"fem", fem_}, {"plg", plg_}}.dump()).result_int();
  };
  EXPECT_EQ(upload("https://evil.example"), 403);
  EXPECT_EQ(upload(""), 403);
  EXPECT_EQ(upload("http://idms.local:8740"), 201);
  EXPECT_EQ(upload("https://lab.example"), 201);
  // A bearer token needs no Origin (not a browser's ambient credential).
  EXPECT_EQ(Upload("hex", fem_, plg_).result_int(), 201);
  // Login from a foreign page is refused; a wrong token gets 401.
  EXPECT_EQ(Call(http::verb::post, "/api/login", "",
                 {{http::field::origin, "https://evil.example"}, {http::field::content_type, "application/json"}},
                 json{{"token", kAdmin}}.dump())
                .result_int(),
            403);
  EXPECT_EQ(Call(http::verb::post, "/api/login", "", {}, json{{"token", "nope-nope-nope-nope"}}.dump()).result_int(),
            401);
  // The token leaving the file ends its cookies; logout ends one.
  auto table = std::make_shared<TokenTable>();
  std::string error;
  ASSERT_TRUE(TokenTable::Parse("observer " + kObserver + "\n", "t", table.get(), &error));
  const auto old = tokens_;
  tokens_ = table;
  EXPECT_EQ(Call(http::verb::get, "/api/models", "", {{http::field::cookie, cookie}}).result_int(), 401);
  tokens_ = old;
  EXPECT_EQ(Call(http::verb::post, "/api/logout", "",
                 {{http::field::cookie, cookie}, {http::field::origin, "http://idms.local:8740"}})
                .result_int(),
            200);
  EXPECT_EQ(Call(http::verb::get, "/api/models", "", {{http::field::cookie, cookie}}).result_int(), 401);
}

TEST_F(ApiTest, MetricsCountRequestsAndLibrary) {
  ASSERT_EQ(Upload("hex", fem_, plg_).result_int(), 201);
  metrics_.CountRequest("PUT", "/api/models/{name}", 201, 0.003, 5000, 300);
  const std::string text = Call(http::verb::get, "/metrics", kObserver).body();
  EXPECT_NE(text.find("idms_http_requests_total{method=\"PUT\",route=\"/api/models/{name}\",status=\"201\"} 1"),
            std::string::npos);
  EXPECT_NE(text.find("idms_http_request_duration_seconds_bucket{route=\"/api/models/{name}\",le=\"0.0025\"} 0"),
            std::string::npos);
  EXPECT_NE(text.find("idms_http_request_duration_seconds_bucket{route=\"/api/models/{name}\",le=\"0.005\"} 1"),
            std::string::npos);
  EXPECT_NE(text.find("idms_models 1\n"), std::string::npos);
  EXPECT_NE(text.find("idms_library_bytes " + std::to_string(fem_.size() + plg_.size()) + "\n"), std::string::npos);
  EXPECT_EQ(Call(http::verb::get, "/metrics", "").result_int(), 401);
}

}  // namespace
}  // namespace idms::server
