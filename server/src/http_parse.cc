// Target, cookie, bearer, media-type and multipart parsing (RFC 3986, 6265, 6750, 9110, 7578).
#include "idms/server/http_parse.h"

#include <algorithm>
#include <cctype>

namespace idms::server {
namespace {

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// %-decoding ('+' is a space in the query only).
bool Decode(std::string_view in, bool plus_is_space, std::string* out) {
  out->clear();
  out->reserve(in.size());
  for (size_t i = 0; i < in.size(); ++i) {
    char c = in[i];
    if (c == '%') {
      if (i + 2 >= in.size()) return false;
      const int hi = HexValue(in[i + 1]), lo = HexValue(in[i + 2]);
      if (hi < 0 || lo < 0) return false;
      c = static_cast<char>(hi * 16 + lo);
      i += 2;
    } else if (c == '+' && plus_is_space) {
      c = ' ';
    }
    if (c == '\0') return false;
    out->push_back(c);
  }
  return true;
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

std::string Lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

bool IEquals(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

// "; name=value; name2="quoted"" after a value: parameters, names lower-cased.
bool ParseParams(std::string_view rest, std::map<std::string, std::string>* params) {
  while (true) {
    rest = Trim(rest);
    if (rest.empty()) return true;
    if (rest.front() != ';') return false;
    rest = Trim(rest.substr(1));
    if (rest.empty()) return true;
    const size_t eq = rest.find('=');
    if (eq == std::string_view::npos || eq == 0) return false;
    const std::string name = Lower(Trim(rest.substr(0, eq)));
    rest = Trim(rest.substr(eq + 1));
    std::string value;
    if (!rest.empty() && rest.front() == '"') {
      size_t i = 1;
      for (; i < rest.size() && rest[i] != '"'; ++i) {
        if (rest[i] == '\\' && i + 1 < rest.size()) ++i;
        value.push_back(rest[i]);
      }
      if (i >= rest.size()) return false;  // unterminated quote
      rest.remove_prefix(i + 1);
    } else {
      const size_t end = rest.find(';');
      value = std::string(Trim(rest.substr(0, end)));
      rest = end == std::string_view::npos ? std::string_view() : rest.substr(end);
    }
    (*params)[name] = std::move(value);
  }
}

}  // namespace

bool ParseTarget(std::string_view target, std::string* path, std::map<std::string, std::string>* query) {
  if (target.empty() || target.front() != '/') return false;
  const size_t q = target.find('?');
  if (!Decode(target.substr(0, q), false, path)) return false;
  for (std::string_view seg : PathSegments(*path)) {
    if (seg == "." || seg == "..") return false;
  }
  query->clear();
  if (q == std::string_view::npos) return true;
  std::string_view rest = target.substr(q + 1);
  while (!rest.empty()) {
    const size_t amp = rest.find('&');
    const std::string_view pair = rest.substr(0, amp);
    rest = amp == std::string_view::npos ? std::string_view() : rest.substr(amp + 1);
    if (pair.empty()) continue;
    const size_t eq = pair.find('=');
    std::string key, value;
    if (!Decode(pair.substr(0, eq), true, &key)) return false;
    if (eq != std::string_view::npos && !Decode(pair.substr(eq + 1), true, &value)) return false;
    (*query)[key] = std::move(value);
  }
  return true;
}

std::vector<std::string_view> PathSegments(std::string_view path) {
  std::vector<std::string_view> out;
  while (!path.empty()) {
    if (path.front() == '/') {
      path.remove_prefix(1);
      continue;
    }
    const size_t slash = path.find('/');
    out.push_back(path.substr(0, slash));
    if (slash == std::string_view::npos) break;
    path.remove_prefix(slash);
  }
  return out;
}

std::optional<std::string_view> CookieValue(std::string_view header, std::string_view name) {
  while (!header.empty()) {
    const size_t semi = header.find(';');
    const std::string_view pair = Trim(header.substr(0, semi));
    header = semi == std::string_view::npos ? std::string_view() : header.substr(semi + 1);
    const size_t eq = pair.find('=');
    if (eq != std::string_view::npos && Trim(pair.substr(0, eq)) == name) return Trim(pair.substr(eq + 1));
  }
  return std::nullopt;
}

std::optional<std::string_view> BearerToken(std::string_view authorization) {
  authorization = Trim(authorization);
  if (authorization.size() < 7 || !IEquals(authorization.substr(0, 7), "bearer ")) return std::nullopt;
  const std::string_view token = Trim(authorization.substr(7));
  if (token.empty()) return std::nullopt;
  return token;
}

bool ParseMediaType(std::string_view header, MediaType* out) {
  const size_t semi = header.find(';');
  const std::string_view type = Trim(header.substr(0, semi));
  if (type.empty() || type.find('/') == std::string_view::npos) return false;
  MediaType m;
  m.type = Lower(type);
  if (semi != std::string_view::npos && !ParseParams(header.substr(semi), &m.params)) return false;
  *out = std::move(m);
  return true;
}

namespace {

// 1*DIGIT, saturating at UINT64_MAX (a larger number is as unsatisfiable, or as clamped).
bool ParseDigits(std::string_view s, uint64_t* value) {
  if (s.empty()) return false;
  uint64_t v = 0;
  for (const char c : s) {
    if (c < '0' || c > '9') return false;
    const uint64_t d = static_cast<uint64_t>(c - '0');
    v = v > (UINT64_MAX - d) / 10 ? UINT64_MAX : v * 10 + d;
  }
  *value = v;
  return true;
}

// One range-spec: false when invalid; else *satisfiable and, if so, *range.
bool ParseRangeSpec(std::string_view spec, uint64_t size, bool* satisfiable, ByteRange* range) {
  const size_t dash = spec.find('-');
  if (dash == std::string_view::npos) return false;
  const std::string_view a = spec.substr(0, dash), b = spec.substr(dash + 1);
  uint64_t first = 0, last = UINT64_MAX, suffix = 0;
  if (a.empty()) {
    // suffix-range: the last N bytes (all of them when N >= size).
    if (!ParseDigits(b, &suffix)) return false;
    *satisfiable = suffix > 0 && size > 0;
    if (*satisfiable) *range = {suffix >= size ? 0 : size - suffix, size - 1};
    return true;
  }
  // int-range: first-last, or first- to the end.
  if (!ParseDigits(a, &first) || (!b.empty() && !ParseDigits(b, &last)) || last < first) return false;
  *satisfiable = first < size;
  if (*satisfiable) *range = {first, std::min(last, size - 1)};
  return true;
}

}  // namespace

RangeRequest ParseRange(std::string_view header, uint64_t size, ByteRange* range) {
  const size_t eq = header.find('=');
  if (eq == std::string_view::npos || !IEquals(header.substr(0, eq), "bytes")) return RangeRequest::kWhole;
  // range-set = 1#range-spec: commas with optional whitespace; empty elements are skipped.
  const std::string_view set = header.substr(eq + 1);
  int specs = 0, satisfiable = 0;
  ByteRange found;
  for (size_t pos = 0; pos <= set.size();) {
    const size_t comma = std::min(set.find(',', pos), set.size());
    const std::string_view spec = Trim(set.substr(pos, comma - pos));
    pos = comma + 1;
    if (spec.empty()) continue;
    bool ok = false;
    if (!ParseRangeSpec(spec, size, &ok, &found)) return RangeRequest::kWhole;
    ++specs, satisfiable += ok ? 1 : 0;
  }
  if (specs == 0) return RangeRequest::kWhole;
  if (satisfiable == 0) return RangeRequest::kUnsatisfiable;
  if (specs > 1) return RangeRequest::kWhole;
  *range = found;
  return RangeRequest::kPartial;
}

bool ValidHost(std::string_view host) {
  std::string_view port;
  if (!host.empty() && host.front() == '[') {
    // IP-literal: IPv6address or IPvFuture; its characters, then "]" and the optional port.
    const size_t close = host.find(']');
    if (close == std::string_view::npos || close == 1) return false;
    for (const char c : host.substr(1, close - 1)) {
      if (!std::isalnum(static_cast<unsigned char>(c)) &&
          std::string_view(":._~!$&'()*+,;=%-").find(c) == std::string_view::npos)
        return false;
    }
    const std::string_view rest = host.substr(close + 1);
    if (!rest.empty() && rest.front() != ':') return false;
    port = rest.empty() ? rest : rest.substr(1);
  } else {
    // reg-name or IPv4address: unreserved, pct-encoded, sub-delims.
    const size_t colon = host.find(':');
    const std::string_view name = host.substr(0, colon);
    for (size_t i = 0; i < name.size(); ++i) {
      const char c = name[i];
      if (c == '%') {
        if (i + 2 >= name.size() || HexValue(name[i + 1]) < 0 || HexValue(name[i + 2]) < 0) return false;
        i += 2;
      } else if (!std::isalnum(static_cast<unsigned char>(c)) &&
                 std::string_view("._~!$&'()*+,;=-").find(c) == std::string_view::npos) {
        return false;
      }
    }
    port = colon == std::string_view::npos ? std::string_view() : host.substr(colon + 1);
  }
  return std::all_of(port.begin(), port.end(), [](char c) { return c >= '0' && c <= '9'; });
}

bool ParseMultipart(std::string_view body, std::string_view boundary, std::vector<FormPart>* parts,
                    std::string* error) {
  if (boundary.empty() || boundary.size() > 70) {
    *error = "multipart boundary must have 1 to 70 characters";
    return false;
  }
  const std::string delim = "--" + std::string(boundary);
  const std::string next = "\r\n" + delim;
  // The preamble ends at the first delimiter.
  size_t pos = body.find(delim);
  if (pos == std::string_view::npos || (pos != 0 && body.find(next) != pos - 2)) {
    *error = "multipart body: no '--" + std::string(boundary) + "' delimiter";
    return false;
  }
  pos += delim.size();
  std::vector<FormPart> out;
  while (true) {
    // After a delimiter: "--" closes the body, CRLF starts a part.
    if (body.substr(pos, 2) == "--") break;
    while (pos < body.size() && (body[pos] == ' ' || body[pos] == '\t')) ++pos;
    if (body.substr(pos, 2) != "\r\n") {
      *error = "multipart body, byte " + std::to_string(pos) + ": expected CRLF after the boundary";
      return false;
    }
    pos += 2;
    // Headers up to the empty line.
    const size_t headers_end = body.find("\r\n\r\n", pos);
    const size_t end = body.find(next, pos);
    if (end == std::string_view::npos) {
      *error = "multipart body, byte " + std::to_string(pos) + ": part without a closing boundary";
      return false;
    }
    FormPart part;
    size_t data_begin = pos;
    if (body.substr(pos, 2) == "\r\n") {
      data_begin = pos + 2;  // a part without headers
    } else if (headers_end == std::string_view::npos || headers_end > end) {
      *error = "multipart body, byte " + std::to_string(pos) + ": part headers without an empty line";
      return false;
    } else {
      std::string_view headers = body.substr(pos, headers_end - pos);
      data_begin = headers_end + 4;
      while (!headers.empty()) {
        const size_t eol = headers.find("\r\n");
        const std::string_view line = headers.substr(0, eol);
        headers = eol == std::string_view::npos ? std::string_view() : headers.substr(eol + 2);
        const size_t colon = line.find(':');
        if (colon == std::string_view::npos) {
          *error = "multipart body, byte " + std::to_string(pos) + ": part header without ':'";
          return false;
        }
        const std::string name = Lower(Trim(line.substr(0, colon)));
        const std::string_view value = Trim(line.substr(colon + 1));
        if (name == "content-disposition") {
          // form-data; name="fem"; filename="x.fem"
          std::map<std::string, std::string> params;
          const size_t semi = value.find(';');
          if (semi == std::string_view::npos || !ParseParams(value.substr(semi), &params)) {
            *error = "multipart body, byte " + std::to_string(pos) + ": bad Content-Disposition";
            return false;
          }
          part.name = params["name"];
          part.filename = params["filename"];
        } else if (name == "content-type") {
          part.content_type = std::string(value);
        }
      }
    }
    part.data = body.substr(data_begin, end - data_begin);
    out.push_back(std::move(part));
    pos = end + next.size();
  }
  *parts = std::move(out);
  return true;
}

}  // namespace idms::server
