// The pieces of an HTTP request the server parses itself (Beast parses the message): the target's
// path and query, cookies, bearer tokens, media types and multipart/form-data bodies. Pure
// functions of their input, no allocation limits of their own (the caller bounds the input).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace idms::server {

// "/api/models/x%2Dy?version=2&a" -> path "/api/models/x-y", query {version: "2", a: ""}.
// False for a target that is not origin-form ("/..."), has a bad %-escape, a NUL, or a path
// segment "." or "..".
bool ParseTarget(std::string_view target, std::string* path, std::map<std::string, std::string>* query);

// Splits a path into its segments: "/api/models/x" -> {"api", "models", "x"}.
std::vector<std::string_view> PathSegments(std::string_view path);

// The value of cookie `name` in a Cookie header ("a=1; idms_session=XYZ").
std::optional<std::string_view> CookieValue(std::string_view header, std::string_view name);

// The token of "Bearer TOKEN" (scheme case-insensitive).
std::optional<std::string_view> BearerToken(std::string_view authorization);

// "multipart/form-data; boundary=abc" -> type "multipart/form-data" (lower case), params.
struct MediaType {
  std::string type;
  std::map<std::string, std::string> params;  // names lower case, values unquoted
};
bool ParseMediaType(std::string_view header, MediaType* out);

// One part of a multipart/form-data body: the form field's name, its filename if any, its bytes
// (a view into the body).
struct FormPart {
  std::string name, filename, content_type;
  std::string_view data;
};
// A Range header (RFC 9110 14.1.2) against a representation of `size` bytes: what to send.
// kPartial: one satisfiable range, *range inclusive and within the representation. kWhole: no
// range to honour: a unit other than bytes, an invalid header (anything but digits in
// first-last / first- / -suffix, last < first; RFC 9110 14.2: ignored), or several ranges (not
// served as multipart/byteranges, which 14.2 allows). kUnsatisfiable: valid, but no range
// overlaps the representation (416).
struct ByteRange {
  uint64_t first = 0, last = 0;
};
enum class RangeRequest { kWhole, kPartial, kUnsatisfiable };
RangeRequest ParseRange(std::string_view header, uint64_t size, ByteRange* range);

// A Host header's value is uri-host [":" port] (RFC 9112 3.2, RFC 3986 3.2.2): an IP literal in
// brackets, or reg-name / IPv4 characters; the port digits only. Empty is allowed.
bool ValidHost(std::string_view host);

// Parses a multipart/form-data body (RFC 7578) with the given boundary. False with *error saying
// what was expected where (byte offset) on a malformed body.
bool ParseMultipart(std::string_view body, std::string_view boundary, std::vector<FormPart>* parts, std::string* error);

}  // namespace idms::server
