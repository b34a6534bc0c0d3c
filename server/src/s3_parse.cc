// What the S3 client reads that it did not write: s3:// URLs from the command line, and the
// store's XML replies (errors, object listings). Pure functions (the s3_parse fuzz target).
#include <charconv>
#include <cstdlib>
#include <vector>

#include "s3_client.h"

namespace idms::server {
namespace {

// The pieces of an XML document, one at a time: a start tag, an end tag, or text between tags
// (entities and CDATA decoded). Enough for S3's replies: no DTDs, attributes skipped.
class XmlScanner {
 public:
  enum class Kind { kOpen, kClose, kText, kEnd, kError };
  explicit XmlScanner(std::string_view xml) : xml_(xml) {}

  Kind Next(std::string* name_or_text) {
    name_or_text->clear();
    if (pos_ >= xml_.size()) return Kind::kEnd;
    if (xml_[pos_] != '<') return Text(name_or_text);
    // Declarations, processing instructions and comments say nothing S3's replies need.
    if (Skip("<?", "?>") || Skip("<!--", "-->")) return Next(name_or_text);
    if (xml_.substr(pos_, 9) == "<![CDATA[") return Text(name_or_text);
    const size_t close = xml_.find('>', pos_);
    if (close == std::string_view::npos) return Kind::kError;
    std::string_view tag = xml_.substr(pos_ + 1, close - pos_ - 1);
    pos_ = close + 1;
    const bool end_tag = !tag.empty() && tag.front() == '/';
    if (end_tag) tag.remove_prefix(1);
    const bool self_closing = !end_tag && !tag.empty() && tag.back() == '/';
    if (self_closing) tag.remove_suffix(1);
    const size_t name_end = tag.find_first_of(" \t\r\n");
    *name_or_text = std::string(tag.substr(0, name_end));
    if (name_or_text->empty()) return Kind::kError;
    if (self_closing) pending_close_ = *name_or_text;
    return end_tag ? Kind::kClose : Kind::kOpen;
  }

  // A self-closing tag is an open then a close: the close is returned by the next call.
  bool TakePendingClose(std::string* name) {
    if (pending_close_.empty()) return false;
    *name = std::move(pending_close_);
    pending_close_.clear();
    return true;
  }

 private:
  bool Skip(std::string_view open, std::string_view close) {
    if (xml_.substr(pos_, open.size()) != open) return false;
    const size_t end = xml_.find(close, pos_ + open.size());
    pos_ = end == std::string_view::npos ? xml_.size() : end + close.size();
    return true;
  }

  // Text up to the next tag, CDATA sections taken literally, entities decoded.
  Kind Text(std::string* out) {
    while (pos_ < xml_.size()) {
      if (xml_.substr(pos_, 9) == "<![CDATA[") {
        const size_t end = xml_.find("]]>", pos_ + 9);
        if (end == std::string_view::npos) return Kind::kError;
        out->append(xml_.substr(pos_ + 9, end - pos_ - 9));
        pos_ = end + 3;
        continue;
      }
      if (xml_[pos_] == '<') break;
      if (xml_[pos_] != '&') {
        out->push_back(xml_[pos_++]);
        continue;
      }
      const size_t semi = xml_.find(';', pos_);
      if (semi == std::string_view::npos || semi - pos_ > 12) return Kind::kError;
      if (!Entity(xml_.substr(pos_ + 1, semi - pos_ - 1), out)) return Kind::kError;
      pos_ = semi + 1;
    }
    return Kind::kText;
  }

  static bool Entity(std::string_view e, std::string* out) {
    if (e == "amp") return out->push_back('&'), true;
    if (e == "lt") return out->push_back('<'), true;
    if (e == "gt") return out->push_back('>'), true;
    if (e == "quot") return out->push_back('"'), true;
    if (e == "apos") return out->push_back('\''), true;
    if (e.size() < 2 || e[0] != '#') return false;
    // A character reference, written out as UTF-8.
    const bool hex = e[1] == 'x' || e[1] == 'X';
    const std::string_view digits = e.substr(hex ? 2 : 1);
    uint32_t cp = 0;
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), cp, hex ? 16 : 10);
    if (ec != std::errc() || end != digits.data() + digits.size() || digits.empty() || cp == 0 || cp > 0x10FFFF ||
        (cp >= 0xD800 && cp <= 0xDFFF))
      return false;
    if (cp < 0x80) {
      out->push_back(static_cast<char>(cp));
    } else if (cp < 0x800) {
      out->push_back(static_cast<char>(0xC0 | (cp >> 6)));
      out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
    } else if (cp < 0x10000) {
      out->push_back(static_cast<char>(0xE0 | (cp >> 12)));
      out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
      out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
    } else {
      out->push_back(static_cast<char>(0xF0 | (cp >> 18)));
      out->push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3F)));
      out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
      out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
    }
    return true;
  }

  std::string_view xml_;
  size_t pos_ = 0;
  std::string pending_close_;
};

// Walks the document: `leaf(path, text)` for the text of each element, its path the element names
// from the root ("ListBucketResult/Contents/Key"). False when the tags do not nest or the
// document is deeper than S3's replies ever are.
template <class F>
bool Walk(std::string_view xml, F leaf, std::string* error) {
  constexpr size_t kMaxDepth = 16;
  XmlScanner scanner(xml);
  std::vector<std::string> stack;
  std::string path, token;
  const auto close = [&](const std::string& name) {
    if (stack.empty() || stack.back() != name) {
      *error = "mismatched </" + name + ">";
      return false;
    }
    stack.pop_back();
    path.resize(path.size() - name.size() - (stack.empty() ? 0 : 1));
    return true;
  };
  while (true) {
    const XmlScanner::Kind kind = scanner.Next(&token);
    switch (kind) {
      case XmlScanner::Kind::kEnd:
        if (!stack.empty()) *error = "the document ends inside <" + stack.back() + ">";
        return stack.empty();
      case XmlScanner::Kind::kError:
        *error = "malformed XML";
        return false;
      case XmlScanner::Kind::kOpen:
        if (stack.size() >= kMaxDepth) {
          *error = "XML nested deeper than " + std::to_string(kMaxDepth);
          return false;
        }
        path += (stack.empty() ? "" : "/") + token;
        stack.push_back(token);
        if (std::string name; scanner.TakePendingClose(&name) && !close(name)) return false;
        break;
      case XmlScanner::Kind::kClose:
        if (!close(token)) return false;
        break;
      case XmlScanner::Kind::kText:
        if (!stack.empty()) leaf(path, token);
        break;
    }
  }
}

bool ParseUint64(const std::string& text, uint64_t* value) {
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), *value);
  return ec == std::errc() && end == text.data() + text.size() && !text.empty();
}

}  // namespace

bool ParseListObjectsV2(std::string_view xml, S3ListPage* page, std::string* error) {
  *page = S3ListPage();
  bool root = false, bad_size = false;
  std::string size_error;
  const bool ok = Walk(
      xml,
      [&](const std::string& path, const std::string& text) {
        if (path.rfind("ListBucketResult", 0) != 0) return;
        root = true;
        if (path == "ListBucketResult/Contents/Key") {
          page->objects.push_back(S3Object{text, 0});
        } else if (path == "ListBucketResult/Contents/Size") {
          if (page->objects.empty() || !ParseUint64(text, &page->objects.back().size)) {
            bad_size = true;
            size_error = text.substr(0, 32);
          }
        } else if (path == "ListBucketResult/IsTruncated") {
          page->truncated = text == "true";
        } else if (path == "ListBucketResult/NextContinuationToken") {
          page->next_token = text;
        }
      },
      error);
  if (!ok) return false;
  if (!root) {
    const std::string s3 = ParseS3Error(xml);
    *error = s3.empty() ? "not a ListBucketResult" : s3;
    return false;
  }
  if (bad_size) {
    *error = "a listed object's Size is not a byte count: '" + size_error + "'";
    return false;
  }
  if (page->truncated && page->next_token.empty()) {
    *error = "a truncated listing without a NextContinuationToken";
    return false;
  }
  return true;
}

std::string ParseS3Error(std::string_view xml) {
  std::string code, message, ignored;
  Walk(
      xml,
      [&](const std::string& path, const std::string& text) {
        if (path == "Error/Code") code = text.substr(0, 128);
        if (path == "Error/Message") message = text.substr(0, 512);
      },
      &ignored);
  if (code.empty()) return "";
  return message.empty() ? code : code + ": " + message;
}

bool IsS3Url(const std::string& text) { return text.rfind("s3://", 0) == 0; }

bool ParseS3Url(const std::string& url, S3Location* location, std::string* error) {
  const auto fail = [&](const std::string& why) {
    *error = "'" + url + "': " + why + " (expected s3://HOST:PORT/BUCKET[?region=REGION])";
    return false;
  };
  if (!IsS3Url(url)) return fail("not an s3:// URL");
  S3Location l;
  std::string rest = url.substr(5);
  std::string query;
  if (const size_t q = rest.find('?'); q != std::string::npos) {
    query = rest.substr(q + 1);
    rest.resize(q);
  }
  const size_t slash = rest.find('/');
  if (slash == std::string::npos) return fail("no bucket");
  const std::string authority = rest.substr(0, slash);
  l.bucket = rest.substr(slash + 1);
  if (!l.bucket.empty() && l.bucket.back() == '/') l.bucket.pop_back();
  // Bucket names as S3 allows them (3-63 of a-z 0-9 . -), so that a path never hides in one.
  if (l.bucket.size() < 3 || l.bucket.size() > 63 ||
      l.bucket.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789.-") != std::string::npos)
    return fail("the bucket must be 3 to 63 characters of a-z, 0-9, '.' and '-'");
  if (authority.find('@') != std::string::npos)
    return fail("credentials do not go in the URL (AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY)");
  // HOST:PORT or [V6]:PORT; the port is required (an S3 server on loopback or a lab network).
  const size_t colon = authority.rfind(':');
  if (colon == std::string::npos || colon == 0) return fail("no :PORT");
  l.host = authority.substr(0, colon);
  if (l.host.front() == '[' && l.host.back() != ']') return fail("an IPv6 address goes in [ ]");
  if (l.host.find_first_of("/ \t") != std::string::npos) return fail("a bad host");
  const std::string port = authority.substr(colon + 1);
  uint64_t p = 0;
  if (!ParseUint64(port, &p) || p == 0 || p > 65535) return fail("the port must be 1-65535");
  l.port = static_cast<uint16_t>(p);
  // Options: region=R, tls=1.
  size_t start = 0;
  while (start < query.size()) {
    size_t end = query.find('&', start);
    if (end == std::string::npos) end = query.size();
    const std::string pair = query.substr(start, end - start);
    const size_t eq = pair.find('=');
    const std::string key = pair.substr(0, eq), value = eq == std::string::npos ? "" : pair.substr(eq + 1);
    if (key == "region" && !value.empty() &&
        value.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789-") == std::string::npos) {
      l.region = value;
    } else if (key == "tls" && (value == "1" || value == "0")) {
      l.tls = value == "1";
    } else {
      return fail("unknown option '" + pair + "' (region=REGION of a-z, 0-9 and '-', tls=0|1)");
    }
    start = end + 1;
  }
  *location = std::move(l);
  return true;
}

std::string S3Location::Describe() const { return "s3://" + host + ":" + std::to_string(port) + "/" + bucket; }

bool S3CredentialsFromEnvironment(S3Credentials* credentials, std::string* error) {
  const char* id = std::getenv("AWS_ACCESS_KEY_ID");
  const char* secret = std::getenv("AWS_SECRET_ACCESS_KEY");
  if (id == nullptr || *id == '\0' || secret == nullptr || *secret == '\0') {
    *error = std::string("S3 credentials: set ") +
             (id == nullptr || *id == '\0' ? "AWS_ACCESS_KEY_ID" : "AWS_SECRET_ACCESS_KEY") + " in the environment";
    return false;
  }
  credentials->access_key = id;
  credentials->secret_key = secret;
  return true;
}

}  // namespace idms::server
