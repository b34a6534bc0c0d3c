// Line, word and number scanning with positions for error messages.
#include "text_scanner.h"

#include <charconv>
#include <cmath>
#include <cstdio>

namespace idms::internal {
namespace {

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

std::string Quote(std::string_view s) {
  constexpr size_t kMax = 24;
  std::string q = "'";
  q.append(s.substr(0, kMax));
  if (s.size() > kMax) q += "...";
  return q + "'";
}

}  // namespace

bool TextScanner::NextLine(char comment) {
  while (next_ < text_.size()) {
    const size_t end = text_.find('\n', next_);
    const size_t stop = end == std::string_view::npos ? text_.size() : end;
    line_ = text_.substr(next_, stop - next_);
    next_ = end == std::string_view::npos ? text_.size() : end + 1;
    line_number_ = ++total_lines_;
    if (comment) {
      const size_t c = line_.find(comment);
      if (c != std::string_view::npos) line_ = line_.substr(0, c);
    }
    pos_ = 0;
    SkipBlanks();
    if (pos_ < line_.size()) return true;
  }
  line_ = {};
  pos_ = 0;
  return false;
}

std::string TextScanner::Item() const {
  if (!kind_) return "the header";
  std::string item = std::string(kind_) + " " + std::to_string(index_);
  return count_ > 0 ? item + " of " + std::to_string(count_) : item;
}

std::string TextScanner::Field(std::string_view what) const {
  return kind_ ? std::string(what) + " of " + Item() : std::string(what);
}

void TextScanner::SkipBlanks() {
  while (pos_ < line_.size() && IsBlank(line_[pos_])) ++pos_;
}

bool TextScanner::Word(std::string_view what, std::string_view* out) {
  SkipBlanks();
  if (pos_ >= line_.size()) return Fail(column(), "expected " + Field(what) + ", found end of line");
  const size_t start = pos_;
  while (pos_ < line_.size() && !IsBlank(line_[pos_])) ++pos_;
  *out = line_.substr(start, pos_ - start);
  return true;
}

bool TextScanner::Int(std::string_view what, int64_t lo, int64_t hi, int64_t* out) {
  SkipBlanks();
  const int col = column();
  std::string_view word;
  if (!Word(what, &word)) return false;
  int64_t value = 0;
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), value);
  if (ec == std::errc::result_out_of_range) {
    return Fail(col, "expected " + Field(what) + ", found out-of-range integer " + Quote(word));
  }
  if (ec != std::errc() || end != word.data() + word.size()) {
    return Fail(col, "expected " + Field(what) + " (an integer), found " + Quote(word));
  }
  if (value < lo || value > hi) {
    return Fail(col, "expected " + Field(what) + " in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                         "], found " + std::to_string(value));
  }
  *out = value;
  return true;
}

bool TextScanner::Real(std::string_view what, double* out) {
  SkipBlanks();
  const int col = column();
  std::string_view word;
  if (!Word(what, &word)) return false;
  double value = 0;
  // from_chars rejects a leading '+'; accept it as every C library does.
  std::string_view digits = word;
  if (digits.size() > 1 && digits[0] == '+' && digits[1] != '-') digits.remove_prefix(1);
  const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  if (ec == std::errc::result_out_of_range) {
    return Fail(col, "expected " + Field(what) + ", found out-of-range number " + Quote(word));
  }
  if (ec != std::errc() || end != digits.data() + digits.size()) {
    return Fail(col, "expected " + Field(what) + " (a number), found " + Quote(word));
  }
  if (!std::isfinite(value)) {
    return Fail(col, "expected " + Field(what) + " (a finite number), found " + Quote(word));
  }
  *out = value;
  return true;
}

bool TextScanner::AtEndOfLine() {
  SkipBlanks();
  return pos_ >= line_.size();
}

bool TextScanner::ExpectEndOfLine() {
  if (AtEndOfLine()) return true;
  const size_t start = pos_;
  size_t stop = start;
  while (stop < line_.size() && !IsBlank(line_[stop])) ++stop;
  return Fail(column(), "expected end of line after " + Item() + ", found extra field " +
                            Quote(line_.substr(start, stop - start)));
}

bool TextScanner::ExpectEndOfFile(std::string_view what) {
  if (!NextLine()) return true;
  return Fail(column(), "expected end of file after " + std::string(what) + ", found an extra line");
}

bool TextScanner::Fail(int col, std::string message) {
  if (error_) {
    error_->file = std::string(file_);
    error_->line = line_number_;
    error_->col = col;
    error_->message = std::move(message);
  }
  return false;
}

bool TextScanner::FailAtEof(std::string message) {
  if (error_) {
    error_->file = std::string(file_);
    error_->line = total_lines_ + (text_.empty() || text_.back() == '\n' ? 1 : 0);
    error_->col = 1;
    error_->message = "unexpected end of file: " + std::move(message);
  }
  return false;
}

bool CheckIsText(std::string_view text, std::string_view file, LoadError* error) {
  int line = 1, col = 1;
  for (size_t i = 0; i < text.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\n') {
      ++line, col = 1;
      continue;
    }
    if (c < 0x20 && c != '\t' && c != '\r' && c != '\v' && c != '\f') {
      if (error) {
        char code[8];
        std::snprintf(code, sizeof code, "0x%02x", c);
        *error = {std::string(file), line, col, std::string("binary data (byte ") + code + "): expected a text file"};
      }
      return false;
    }
    ++col;
  }
  return true;
}

}  // namespace idms::internal
