// Private: the lexical layer shared by the ASF and AMC readers.
//
// Both formats are line-oriented. On a line, `,` `(` `)` and any ASCII
// whitespace separate tokens and `#` starts a comment. Lines end at "\n",
// "\r\n" or a lone "\r". Columns are 1-based byte offsets.
#pragma once

#include <Eigen/Core>
#include <array>
#include <charconv>
#include <cmath>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/core/rotation.h"

namespace gmr::acclaim_detail {

struct Token {
  std::string_view text;
  int column = 0;
};

struct Line {
  int number = 0;             // 1-based
  std::string_view raw;       // without the line break
  std::vector<Token> tokens;  // comment stripped
};

inline bool is_separator(char c) {
  return c == ' ' || c == '\t' || c == ',' || c == '(' || c == ')' || c == '\v' || c == '\f';
}

// Reads lines one at a time, with one line of look-ahead (limits span lines).
class LineReader {
 public:
  explicit LineReader(std::string_view text) : text_(text) {}

  // Next line, or false at the end of the text.
  bool next(Line& out) {
    if (has_peeked_) {
      std::swap(out, peeked_);
      has_peeked_ = false;
      return true;
    }
    return read(out);
  }
  // The line next() would return, without consuming it; nullptr at the end.
  const Line* peek() {
    if (!has_peeked_) {
      if (!read(peeked_)) return nullptr;
      has_peeked_ = true;
    }
    return &peeked_;
  }
  // Number of the last line read, at least 1 (for errors at the end of the text).
  int last_line() const { return line_ > 0 ? line_ : 1; }

 private:
  bool read(Line& out) {
    if (pos_ >= text_.size()) return false;
    std::size_t end = pos_;
    while (end < text_.size() && text_[end] != '\n' && text_[end] != '\r') ++end;
    out.raw = text_.substr(pos_, end - pos_);
    out.number = ++line_;
    if (end < text_.size() && text_[end] == '\r' && end + 1 < text_.size() && text_[end + 1] == '\n') {
      pos_ = end + 2;
    } else {
      pos_ = end + 1;
    }
    tokenize(out);
    return true;
  }

  static void tokenize(Line& line) {
    line.tokens.clear();
    const std::string_view s = line.raw;
    std::size_t i = 0;
    while (i < s.size()) {
      if (s[i] == '#') break;
      if (is_separator(s[i])) {
        ++i;
        continue;
      }
      const std::size_t b = i;
      while (i < s.size() && !is_separator(s[i]) && s[i] != '#') ++i;
      line.tokens.push_back(Token{s.substr(b, i - b), static_cast<int>(b) + 1});
    }
  }

  std::string_view text_;
  std::size_t pos_ = 0;
  int line_ = 0;
  Line peeked_;
  bool has_peeked_ = false;
};

// A number: optional sign, digits with an optional point, optional exponent of
// any length (`e-015`); `inf`/`nan` only when allow_non_finite. The whole token
// must be the number (so `0.0-7.5` is rejected).
inline std::optional<double> parse_number(std::string_view t, bool allow_non_finite = false) {
  std::string_view s = t;
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty() || s.front() == '+') return std::nullopt;
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v, std::chars_format::general);
  if (ec == std::errc::result_out_of_range) {
    // Underflow reads as 0, overflow as infinity (rejected below unless allowed).
    return std::nullopt;
  }
  if (ec != std::errc() || ptr != s.data() + s.size()) return std::nullopt;
  if (!allow_non_finite && !std::isfinite(v)) return std::nullopt;
  return v;
}

// A non-negative decimal integer (frame numbers, ids), at most 18 digits.
inline std::optional<long long> parse_integer(std::string_view t) {
  if (t.empty() || t.size() > 18) return std::nullopt;
  long long v = 0;
  for (char c : t) {
    if (c < '0' || c > '9') return std::nullopt;
    v = v * 10 + (c - '0');
  }
  return v;
}

inline char lower(char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c; }

inline std::string to_lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = lower(c);
  return out;
}

inline bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (lower(a[i]) != lower(b[i])) return false;
  }
  return true;
}

inline Error error_at(std::string_view file, int line, int column, std::string message) {
  return Error{std::string(file), line, column, std::move(message)};
}

inline std::string quote_text(std::string_view s) {
  std::string out = "'";
  // Keep messages on one line and short even for binary garbage.
  for (char c : s.substr(0, 64)) out += (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) ? '?' : c;
  if (s.size() > 64) out += "...";
  out += '\'';
  return out;
}

// Writers: numbers in their shortest round-tripping form.
inline void put(std::string& out, double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

inline void put3(std::string& out, const Eigen::Vector3d& v) {
  put(out, v.x());
  out += ' ';
  put(out, v.y());
  out += ' ';
  put(out, v.z());
}

inline void put_order(std::string& out, const std::array<Axis, 3>& order) {
  for (Axis a : order) out += static_cast<char>('X' + static_cast<int>(a));
}

}  // namespace gmr::acclaim_detail
