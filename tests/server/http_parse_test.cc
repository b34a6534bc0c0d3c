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

// RFC 9110 14.1.2 strictly: digits only; an invalid header is ignored (the whole), a valid one
// that misses the representation is a 416.
TEST(ParseRange, FirstLastFirstAndSuffixRanges) {
  ByteRange r;
  auto partial = [&](std::string_view header, uint64_t first, uint64_t last) {
    r = ByteRange{99, 99};
    EXPECT_EQ(ParseRange(header, 1000, &r), RangeRequest::kPartial) << header;
    EXPECT_EQ(r.first, first) << header;
    EXPECT_EQ(r.last, last) << header;
  };
  partial("bytes=0-499", 0, 499);
  partial("bytes=500-", 500, 999);
  partial("bytes=-200", 800, 999);
  partial("bytes=-2000", 0, 999);
  partial("bytes=990-5000", 990, 999);
  partial("bytes=999-999", 999, 999);
  partial("BYTES=1-2", 1, 2);
  partial("bytes= 1-2 ", 1, 2);
  partial("bytes=,1-2,", 1, 2);  // empty list elements are skipped
  partial("bytes=0-18446744073709551616", 0, 999);
}

TEST(ParseRange, InvalidHeadersAreIgnored) {
  ByteRange r;
  for (std::string_view header : {"bytes=--5",    "bytes=0x10-0x20", "bytes=5-1",  "bytes=a-b",  "bytes=",
                                  "bytes=-",      "bytes=,",         "bytes=1 -2", "bytes=1- 2", "bytes=+1-2",
                                  "bytes=1-+2",   "bytes=1-2-3",     "bytes=-5-",  "bytes=1",    "bytes=-1.5",
                                  "bytes 1-2",    "bytes=1-2,x",     "items=0-5",  "",           "=0-5",
                                  "bytes=0-1,5-6"})
    EXPECT_EQ(ParseRange(header, 1000, &r), RangeRequest::kWhole) << header;
}

TEST(ParseRange, RangesBeyondTheRepresentationAreUnsatisfiable) {
  ByteRange r;
  for (std::string_view header :
       {"bytes=1000-", "bytes=1000-2000", "bytes=-0", "bytes=18446744073709551616-", "bytes=2000-,3000-4000"})
    EXPECT_EQ(ParseRange(header, 1000, &r), RangeRequest::kUnsatisfiable) << header;
  EXPECT_EQ(ParseRange("bytes=0-", 0, &r), RangeRequest::kUnsatisfiable);
  EXPECT_EQ(ParseRange("bytes=-5", 0, &r), RangeRequest::kUnsatisfiable);
  // One of several in range: the whole, not a 416.
  EXPECT_EQ(ParseRange("bytes=2000-,0-5", 1000, &r), RangeRequest::kWhole);
}

TEST(ValidHost, NamesAddressesAndPortsOnly) {
  for (std::string_view host : {"", "localhost", "idms.local:8740", "127.0.0.1:80", "[::1]", "[::1]:8740",
                                "[fe80::1%25eth0]", "a-b_c~d.example", "xn--bcher-kva.example", "host:"})
    EXPECT_TRUE(ValidHost(host)) << host;
  for (std::string_view host :
       {"a b", "a/b", "user@host", "host:80x", "[::1", "[]", "[::1]x", "h%zz", "a\tb", "host:80:81", "a\"b"})
    EXPECT_FALSE(ValidHost(host)) << host;
}

}  // namespace
}  // namespace idms::server
