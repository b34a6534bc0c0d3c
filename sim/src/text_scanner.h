// A line-oriented scanner for the whitespace-separated text formats (.fem, .plg, .obj):
// it tracks line and column so every parse error can say FILE:LINE:COL.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "idms/sim/model_io.h"

namespace idms::internal {

class TextScanner {
 public:
  TextScanner(std::string_view text, std::string_view file, LoadError* error)
      : text_(text), file_(file), error_(error) {}

  // Advances to the next line holding anything but blanks (and, if `comment` is non-zero,
  // text after it). Returns false at end of input.
  bool NextLine(char comment = 0);

  // The current line (without the newline) and its 1-based number.
  std::string_view line() const { return line_; }
  int line_number() const { return line_number_; }

  // Names the item the current line holds ("atom", 3, 58 -> "atom 3 of 58"; count 0 -> "atom 3";
  // none yet -> "the header") for messages;
  // formatted only when an error is reported, so the happy path builds no strings.
  void SetItem(const char* kind, int64_t index, int64_t count) { kind_ = kind, index_ = index, count_ = count; }
  std::string Item() const;

  // Field reading on the current line; `what` names the field ("x", "mass"), to which the
  // item is appended. Each returns false and sets the error on failure.
  bool Word(std::string_view what, std::string_view* out);
  bool Int(std::string_view what, int64_t lo, int64_t hi, int64_t* out);
  bool Real(std::string_view what, double* out);  // finite numbers only
  bool AtEndOfLine();                             // skips blanks; true if nothing is left
  bool ExpectEndOfLine();                         // error if anything but blanks remains
  bool ExpectEndOfFile(std::string_view what);    // error if another non-blank line follows
  int column() const { return static_cast<int>(pos_) + 1; }

  // Sets the error at the current line and the given 1-based column (0 = whole line).
  bool Fail(int col, std::string message);
  bool FailAtEof(std::string message);

 private:
  void SkipBlanks();
  std::string Field(std::string_view what) const;  // "x of atom 3 of 58"

  std::string_view text_;
  std::string_view file_;
  LoadError* error_;
  size_t next_ = 0;        // offset of the next line in text_
  std::string_view line_;  // current line
  int line_number_ = 0;
  int total_lines_ = 0;  // lines consumed so far (for end-of-file messages)
  size_t pos_ = 0;       // offset in line_
  const char* kind_ = nullptr;
  int64_t index_ = 0, count_ = 0;
};

// Checks that `text` is plain text: no NUL or other control bytes except tab, CR and LF.
// Returns false and sets the error (with line and column of the first bad byte) otherwise.
bool CheckIsText(std::string_view text, std::string_view file, LoadError* error);

}  // namespace idms::internal
