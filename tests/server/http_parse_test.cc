// Request targets, cookies, bearer tokens, media types and multipart bodies.
#include "idms/server/http_parse.h"

#include <gtest/gtest.h>

namespace idms::server {
namespace {

TEST(ParseTarget, DecodesPathAndQueryAndRejectsDotSegments) {
  std::string path;
  std::map<std::string, std::string> query;
  ASSERT_TRUE(ParseTarget("/api/models/a%2Db?version=2&x&y=a+b", &path, &query));
  EXPECT_EQ(path, "/api/models/a-b");
  EXPECT_EQ(query.at("version"), "2");
  EXPECT_EQ(query.at("x"), "");
  EXPECT_EQ(query.at("y"), "a b");
  EXPECT_FALSE(ParseTarget("/api/models/../../etc", &path, &query));
  EXPECT_FALSE(ParseTarget("/api/models/%2e%2e/x", &path, &query));
  EXPECT_FALSE(ParseTarget("/a%zz", &path, &query));
  EXPECT_FALSE(ParseTarget("/a%4", &path, &query));
  EXPECT_FALSE(ParseTarget("/a%00b", &path, &query));
  EXPECT_FALSE(ParseTarget("http://x/a", &path, &query));
  EXPECT_FALSE(ParseTarget("", &path, &query));
}

TEST(CookiesAndBearer, FindTheirValues) {
  EXPECT_EQ(CookieValue("a=1; idms_session=XYZ; b=2", "idms_session").value(), "XYZ");
  EXPECT_FALSE(CookieValue("a=1; idms_sessionx=XYZ", "idms_session"));
  EXPECT_EQ(BearerToken("Bearer abc").value(), "abc");
  EXPECT_EQ(BearerToken("bearer   abc ").value(), "abc");
  EXPECT_FALSE(BearerToken("Basic abc"));
  EXPECT_FALSE(BearerToken("Bearer "));
}

TEST(MediaType, ParsesTypeAndQuotedParameters) {
  MediaType m;
  ASSERT_TRUE(ParseMediaType("Multipart/Form-Data; boundary=\"a b\"; charset=utf-8", &m));
  EXPECT_EQ(m.type, "multipart/form-data");
  EXPECT_EQ(m.params.at("boundary"), "a b");
  EXPECT_EQ(m.params.at("charset"), "utf-8");
  EXPECT_FALSE(ParseMediaType("nonsense", &m));
  EXPECT_FALSE(ParseMediaType("text/plain; x=\"open", &m));
}

TEST(Multipart, SplitsPartsAsCurlSendsThem) {
  const std::string body =
      "--XyZ\r\nContent-Disposition: form-data; name=\"fem\"; filename=\"a.fem\"\r\nContent-Type: "
      "application/octet-stream\r\n\r\nline1\r\nline2\r\n--XyZ\r\nContent-Disposition: form-data; "
      "name=\"description\"\r\n\r\nhello\r\n--XyZ--\r\n";
  std::vector<FormPart> parts;
  std::string error;
  ASSERT_TRUE(ParseMultipart(body, "XyZ", &parts, &error)) << error;
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts[0].name, "fem");
  EXPECT_EQ(parts[0].filename, "a.fem");
  EXPECT_EQ(parts[0].data, "line1\r\nline2");
  EXPECT_EQ(parts[1].name, "description");
  EXPECT_EQ(parts[1].data, "hello");
}

TEST(Multipart, MalformedBodiesSayWhere) {
  std::vector<FormPart> parts;
  std::string error;
  EXPECT_FALSE(ParseMultipart("no boundary here", "b", &parts, &error));
  EXPECT_NE(error.find("no '--b' delimiter"), std::string::npos);
  EXPECT_FALSE(ParseMultipart("--b\r\nContent-Disposition: form-data; name=\"x\"\r\n\r\ndata never closed", "b", &parts,
                              &error));
  EXPECT_NE(error.find("closing boundary"), std::string::npos);
  EXPECT_FALSE(ParseMultipart("--b\r\nBroken header\r\n\r\nx\r\n--b--", "b", &parts, &error));
  EXPECT_NE(error.find("without ':'"), std::string::npos);
  EXPECT_FALSE(ParseMultipart("--b", "", &parts, &error));
}

}  // namespace
}  // namespace idms::server
