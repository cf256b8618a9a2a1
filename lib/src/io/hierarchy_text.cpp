#include "hierarchy_text.h"

#include "gmr/core/file_util.h"
#include "gmr/core/limits.h"

#include "core/number_format.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <unordered_map>
#include <unordered_set>

namespace gmr::detail {
namespace {

// Deepest joint nesting accepted: far beyond any real skeleton, and it keeps
// hostile input from growing the open-block stack without bound.
constexpr std::size_t kMaxDepth = 1024;
constexpr std::size_t kMaxWarnings = 100;

// Whitespace as the C locale's isspace: space, \t, \n, \v, \f, \r.
constexpr std::array<bool, 256> make_space_table() {
  std::array<bool, 256> t{};
  t[' '] = t['\t'] = t['\n'] = t['\v'] = t['\f'] = t['\r'] = true;
  return t;
}
constexpr std::array<bool, 256> kSpace = make_space_table();
inline bool is_space(char c) { return kSpace[static_cast<unsigned char>(c)]; }

// ASCII case-insensitive comparison (keywords and channel names only).
bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    auto lower = [](char c) { return c >= 'A' && c <= 'Z' ? static_cast<char>(c + 32) : c; };
    if (lower(a[i]) != lower(b[i])) return false;
  }
  return true;
}

bool istarts_with(std::string_view s, std::string_view prefix) {
  return s.size() >= prefix.size() && iequals(s.substr(0, prefix.size()), prefix);
}

// A token as it appears in a message: quoted, shortened, control bytes escaped.
std::string quote(std::string_view tok) {
  if (tok.empty()) return "end of file";
  std::string out = "'";
  const std::size_t n = std::min<std::size_t>(tok.size(), 40);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(tok[i]);
    if (c < 0x20 || c == 0x7f) {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    } else {
      out += static_cast<char>(c);
    }
  }
  if (n < tok.size()) out += "...";
  out += "'";
  return out;
}

// Index of the first control character of a name (tabs are allowed inside
// names), or npos. Names with one could not be written back.
std::size_t control_char(std::string_view name) {
  for (std::size_t i = 0; i < name.size(); ++i) {
    const auto u = static_cast<unsigned char>(name[i]);
    if ((u < 0x20 && u != '\t') || u == 0x7f) return i;
  }
  return std::string_view::npos;
}

// Reads a double from [p, end): an optional '+', then what std::from_chars
// accepts. Returns the end of the number, or nullptr when there is none.
// Reads a double from [p, end): an optional '+', then what std::from_chars
// accepts. Returns the end of the number, or nullptr when there is none.
// Out-of-range text gives +-inf (caught by the finiteness checks) or, for
// underflow, the nearest double (what strtod gives).
inline const char* read_double_slow(const char* p, const char* end, double& out) {
  if (p < end && *p == '+' && p + 1 < end && *(p + 1) != '-' && *(p + 1) != '+') ++p;
  const auto r = std::from_chars(p, end, out);
  if (r.ec == std::errc()) return r.ptr;
  if (r.ec != std::errc::result_out_of_range) return nullptr;
  const std::size_t len = static_cast<std::size_t>(r.ptr - p);
  if (len >= 128) {
    out = std::numeric_limits<double>::infinity();
    return r.ptr;
  }
  char buf[128];
  std::copy(p, r.ptr, buf);
  buf[len] = '\0';
  out = std::strtod(buf, nullptr);
  return r.ptr;
}

constexpr double kPow10[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                             1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

// Same result as read_double_slow(). Fast path for the plain decimals that
// mocap files are made of ("-12.345678", "0"): when the digits form an integer
// m <= 2^53 and there are k <= 22 decimals, m and 10^k are exact doubles and
// one division is correctly rounded, so m / 10^k is the exact nearest double
// (Clinger's fast path, also the first step of std::from_chars). Anything else
// (exponents, long mantissas, '+', inf/nan) goes to std::from_chars.
inline const char* read_double(const char* p, const char* end, double& out) {
  const char* s = p;
  const bool negative = s < end && *s == '-';
  s += negative ? 1 : 0;
  std::uint64_t m = 0;
  int digits = 0, decimals = 0;
  while (s < end && static_cast<unsigned>(*s - '0') < 10 && digits < 19) {
    m = m * 10 + static_cast<unsigned>(*s - '0');
    ++s;
    ++digits;
  }
  if (s < end && *s == '.') {
    ++s;
    while (s < end && static_cast<unsigned>(*s - '0') < 10 && digits < 19) {
      m = m * 10 + static_cast<unsigned>(*s - '0');
      ++s;
      ++digits;
      ++decimals;
    }
  }
  const bool plain = digits > 0 && m <= (std::uint64_t{1} << 53) && decimals <= 22 &&
                     (s == end || (static_cast<unsigned>(*s - '0') >= 10 && *s != 'e' && *s != 'E' && *s != '.'));
  if (!plain) return read_double_slow(p, end, out);
  double v = static_cast<double>(m);
  if (decimals != 0) v /= kPow10[decimals];
  out = negative ? -v : v;
  return s;
}

class Parser {
 public:
  Parser(std::string_view text, std::string_view label, Dialect dialect, Warnings* warnings)
      : text_(text), label_(label), dialect_(dialect), warnings_(warnings) {}

  Result<Motion> run();

 private:
  struct Pending {
    Joint joint;
    std::size_t decl_offset = 0;  // where the joint's keyword is (for messages)
    bool end_site = false;
    bool has_offset = false;
    bool has_channels = false;
    std::string soft_link;  // GMR: name after SOFTLINK
    std::size_t soft_link_offset = 0;
    int next_end_site = 1;  // see default_end_site_name()
  };

  // --- locations and messages
  Error error_at(std::size_t offset, std::string message) const {
    Error e;
    e.file = std::string(label_);
    const auto [line, col] = locate(offset);
    e.line = line;
    e.column = col;
    e.message = std::move(message);
    return e;
  }
  // At most kMaxWarnings are kept (each costs a scan for its line number);
  // the rest are counted and reported in one last warning.
  void warn_at(std::size_t offset, std::string message) {
    if (warnings_ == nullptr) return;
    if (warned_ >= kMaxWarnings) {
      ++warned_;
      return;
    }
    ++warned_;
    warnings_->push_back(error_at(offset, std::move(message)));
  }
  void finish_warnings() {
    if (warnings_ != nullptr && warned_ > kMaxWarnings) {
      Error e;
      e.file = std::string(label_);
      e.message = std::to_string(warned_ - kMaxWarnings) + " more warnings not shown";
      warnings_->push_back(std::move(e));
    }
  }
  // 1-based line and column of a byte offset. Lines end at \n, \r\n or a lone
  // \r. Computed only when a message needs it, so the fast path counts nothing.
  std::pair<int, int> locate(std::size_t offset) const {
    offset = std::min(offset, text_.size());
    std::size_t line = 1;
    std::size_t line_start = 0;
    for (std::size_t i = 0; i < offset; ++i) {
      const char c = text_[i];
      if (c == '\n' || (c == '\r' && (i + 1 >= text_.size() || text_[i + 1] != '\n'))) {
        ++line;
        line_start = i + 1;
      }
    }
    constexpr std::size_t kMaxInt = static_cast<std::size_t>(std::numeric_limits<int>::max());
    return {static_cast<int>(std::min(line, kMaxInt)), static_cast<int>(std::min(offset - line_start + 1, kMaxInt))};
  }
  int line_of(std::size_t offset) const { return locate(offset).first; }

  // --- tokens (hierarchy only; the MOTION rows have their own loop)
  void skip_space() {
    while (pos_ < text_.size() && is_space(text_[pos_])) ++pos_;
  }
  // Next token: a run of non-space bytes, or a single '{' or '}'. Empty at end.
  std::string_view peek_token() {
    skip_space();
    std::size_t e = pos_;
    if (e < text_.size() && (text_[e] == '{' || text_[e] == '}')) return text_.substr(pos_, 1);
    while (e < text_.size() && !is_space(text_[e]) && text_[e] != '{' && text_[e] != '}') ++e;
    return text_.substr(pos_, e - pos_);
  }
  std::string_view next_token() {
    const std::string_view t = peek_token();
    token_offset_ = pos_;
    pos_ += t.size();
    return t;
  }
  // The rest of the current line, trimmed (joint names may hold spaces).
  std::string_view rest_of_line() {
    while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\t')) ++pos_;
    const std::size_t b = pos_;
    while (pos_ < text_.size() && text_[pos_] != '\n' && text_[pos_] != '\r') ++pos_;
    std::size_t e = pos_;
    while (e > b && is_space(text_[e - 1])) --e;
    return text_.substr(b, e - b);
  }

  Status expect_keyword(std::string_view keyword, std::string_view what) {
    const std::string_view t = next_token();
    if (!iequals(t, keyword)) return error_at(token_offset_, "expected " + std::string(what) + ", found " + quote(t));
    return Ok{};
  }
  Status read_number(double& out, std::string_view what) {
    const std::string_view t = next_token();
    const char* e = t.empty() ? nullptr : read_double(t.data(), t.data() + t.size(), out);
    if (e == nullptr) return error_at(token_offset_, "expected " + std::string(what) + ", found " + quote(t));
    if (e != t.data() + t.size()) {
      return error_at(token_offset_ + static_cast<std::size_t>(e - t.data()),
                      "malformed number " + quote(t) + ": expected whitespace after " +
                          quote(t.substr(0, static_cast<std::size_t>(e - t.data()))) + " (numbers run together?)");
    }
    if (!std::isfinite(out)) return error_at(token_offset_, std::string(what) + " is not finite: " + quote(t));
    return Ok{};
  }
  Status read_count(std::string_view t, std::size_t t_offset, std::uint64_t& out, std::string_view what) {
    const auto r = std::from_chars(t.data(), t.data() + t.size(), out);
    if (t.empty() || r.ec == std::errc::invalid_argument || r.ptr != t.data() + t.size())
      return error_at(t_offset, "expected " + std::string(what) + " (a non-negative integer), found " + quote(t));
    if (r.ec != std::errc()) return error_at(t_offset, std::string(what) + " out of range: " + quote(t));
    return Ok{};
  }

  // --- grammar
  Status read_header();
  Status read_tree();
  Status read_joint_name(std::string_view keyword, std::string& out_name, bool& out_brace_taken);
  Status add_joint(Pending pending, std::size_t name_offset);
  Status read_channels(Pending& j);
  Result<Motion> read_motion();

  std::string_view text_;
  std::string_view label_;
  Dialect dialect_;
  Warnings* warnings_;
  std::size_t pos_ = 0;
  std::size_t token_offset_ = 0;
  std::size_t warned_ = 0;

  std::vector<Pending> joints_;
  std::unordered_map<std::string, int> names_;
  std::vector<int> channel_decl_order_;  // joints in the order their CHANNELS lines appear
};

Status Parser::read_header() {
  // A UTF-8 byte order mark is not text; skip it.
  if (text_.substr(0, 3) == "\xEF\xBB\xBF") pos_ = 3;
  if (dialect_ == Dialect::kGmr) {
    const std::string_view t = next_token();
    if (t != "GMR")
      return error_at(token_offset_,
                      "expected the format line 'GMR " + std::to_string(kGmrFormatVersion) + "', found " + quote(t));
    const std::string_view v = next_token();
    std::uint64_t version = 0;
    if (auto s = read_count(v, token_offset_, version, "a format version"); !s) return s;
    if (version != static_cast<std::uint64_t>(kGmrFormatVersion))
      return error_at(token_offset_, "unsupported GMR format version " + std::string(v) +
                                         " (this reader reads version " + std::to_string(kGmrFormatVersion) + ")");
  }
  return expect_keyword("HIERARCHY", "'HIERARCHY'");
}

Status Parser::read_joint_name(std::string_view keyword, std::string& out_name, bool& out_brace_taken) {
  const std::size_t at = pos_;
  std::string_view name = rest_of_line();
  out_brace_taken = false;
  // "JOINT Name {" on one line: the brace is not part of the name.
  if (!name.empty() && name.back() == '{') {
    name.remove_suffix(1);
    while (!name.empty() && is_space(name.back())) name.remove_suffix(1);
    out_brace_taken = true;
  }
  if (name.empty() && keyword != "End Site") return error_at(at, "expected a joint name after " + std::string(keyword));
  if (auto bad = control_char(name); bad != std::string_view::npos)
    return error_at(static_cast<std::size_t>(name.data() - text_.data()) + bad,
                    "joint name " + quote(name) + " contains a control character");
  out_name.assign(name);
  return Ok{};
}

Status Parser::add_joint(Pending pending, std::size_t name_offset) {
  const auto [it, inserted] = names_.emplace(pending.joint.name, static_cast<int>(joints_.size()));
  if (!inserted) {
    return error_at(name_offset,
                    "duplicate joint name " + quote(pending.joint.name) + " (first at line " +
                        std::to_string(line_of(joints_[static_cast<std::size_t>(it->second)].decl_offset)) + ")");
  }
  joints_.push_back(std::move(pending));
  return Ok{};
}

Status Parser::read_channels(Pending& j) {
  const std::size_t kw = token_offset_;
  if (j.has_channels) {
    return error_at(kw, "second CHANNELS line for joint " + quote(j.joint.name) + " (first at line " +
                            std::to_string(line_of(j.decl_offset)) + ")");
  }
  j.has_channels = true;
  const std::string_view t = next_token();
  std::uint64_t n = 0;
  if (auto s = read_count(t, token_offset_, n, "a channel count"); !s) return s;
  if (n > 6) return error_at(token_offset_, "channel count " + std::string(t) + " out of range: expected 0 to 6");
  unsigned seen = 0;
  for (std::uint64_t i = 0; i < n; ++i) {
    const std::string_view c = next_token();
    const auto type = parse_channel(c);
    if (!type) {
      return error_at(token_offset_, "CHANNELS " + std::to_string(n) + " lists " + std::to_string(i) +
                                         " channel name(s), then " + quote(c) +
                                         ": expected Xposition, Yposition, Zposition, Xrotation, Yrotation or "
                                         "Zrotation");
    }
    const unsigned bit = 1u << static_cast<unsigned>(*type);
    if (seen & bit) return error_at(token_offset_, "channel " + quote(c) + " listed twice");
    seen |= bit;
    j.joint.channels.push_back(*type);
  }
  // More names than the count declares would shift every value of the row.
  if (const std::string_view extra = peek_token(); parse_channel(extra)) {
    return error_at(pos_,
                    "CHANNELS declares " + std::to_string(n) + " channel(s) but more names follow: " + quote(extra));
  }
  return Ok{};
}

// One ROOT block and everything in it. The open blocks are a stack of joint
// indices (never references into joints_, which grows as children are read).
Status Parser::read_tree() {
  struct Open {
    int joint;
    std::size_t brace_offset;
  };
  std::vector<Open> stack;

  auto open_joint = [&](std::string_view keyword, int parent, bool end_site) -> Status {
    const std::size_t kw = token_offset_;
    if (stack.size() >= kMaxDepth)
      return error_at(kw, "joints nested deeper than " + std::to_string(kMaxDepth) + " levels");
    std::string name;
    bool brace_taken = false;
    const std::size_t name_offset = pos_;
    if (auto s = read_joint_name(keyword, name, brace_taken); !s) return s;
    if (end_site && name.empty()) {
      Pending& pj = joints_[static_cast<std::size_t>(parent)];
      name = default_end_site_name(
          pj.joint.name, [&](const std::string& n) { return names_.count(n) != 0; }, pj.next_end_site);
    }
    Pending p;
    p.joint.name = std::move(name);
    p.joint.parent = parent;
    p.decl_offset = kw;
    p.end_site = end_site;
    if (auto s = add_joint(std::move(p), name_offset); !s) return s;
    std::size_t brace = pos_;
    if (!brace_taken) {
      const std::string_view t = next_token();
      brace = token_offset_;
      if (t != "{") {
        return error_at(token_offset_, "expected '{' after " + std::string(keyword) + " " +
                                           quote(joints_.back().joint.name) + ", found " + quote(t));
      }
    }
    stack.push_back({static_cast<int>(joints_.size()) - 1, brace});
    return Ok{};
  };

  next_token();  // ROOT, checked by the caller
  if (auto s = open_joint("ROOT", kNoParent, false); !s) return s;

  while (!stack.empty()) {
    const int cur = stack.back().joint;
    const std::string_view t = next_token();
    const std::size_t at = token_offset_;
    // Index, not reference: open_joint() below may grow joints_.
    auto J = [&]() -> Pending& { return joints_[static_cast<std::size_t>(cur)]; };
    if (t == "}") {
      if (!J().has_offset) warn_at(J().decl_offset, "joint " + quote(J().joint.name) + " has no OFFSET; using 0 0 0");
      stack.pop_back();
    } else if (iequals(t, "OFFSET")) {
      if (J().has_offset) {
        return error_at(at, "second OFFSET for joint " + quote(J().joint.name) + " (first one stands)");
      }
      J().has_offset = true;
      for (int i = 0; i < 3; ++i) {
        double v = 0;
        if (auto s = read_number(v, "an OFFSET value"); !s) return s;
        J().joint.offset[i] = v;
      }
    } else if (iequals(t, "CHANNELS")) {
      if (auto s = read_channels(J()); !s) return s;
      channel_decl_order_.push_back(cur);
    } else if (iequals(t, "JOINT")) {
      if (J().end_site) return error_at(at, "an End Site cannot have children (found JOINT)");
      if (auto s = open_joint("JOINT", cur, false); !s) return s;
    } else if (dialect_ == Dialect::kBvh && iequals(t, "End")) {
      if (J().end_site) return error_at(at, "an End Site cannot have children (found End Site)");
      const std::string_view site = next_token();
      if (!iequals(site, "Site")) return error_at(token_offset_, "expected 'Site' after 'End', found " + quote(site));
      if (auto s = open_joint("End Site", cur, true); !s) return s;
    } else if (dialect_ == Dialect::kGmr && iequals(t, "SOFTLINK")) {
      if (J().joint.parent != kNoParent) return error_at(at, "SOFTLINK is allowed on a ROOT only");
      if (!J().soft_link.empty()) return error_at(at, "second SOFTLINK for joint " + quote(J().joint.name));
      const std::size_t name_at = pos_;
      const std::string_view name = rest_of_line();
      if (name.empty()) return error_at(name_at, "expected a joint name after SOFTLINK");
      if (auto bad = control_char(name); bad != std::string_view::npos)
        return error_at(static_cast<std::size_t>(name.data() - text_.data()) + bad,
                        "joint name " + quote(name) + " contains a control character");
      J().soft_link.assign(name);
      J().soft_link_offset = name_at;
    } else {
      const std::string expected = dialect_ == Dialect::kBvh ? "OFFSET, CHANNELS, JOINT, End Site or '}'"
                                                             : "OFFSET, CHANNELS, SOFTLINK, JOINT or '}'";
      if (t.empty() || iequals(t, "ROOT") || iequals(t, "MOTION")) {
        return error_at(at, "expected " + expected + " (joint " + quote(J().joint.name) + " opened at line " +
                                std::to_string(line_of(stack.back().brace_offset)) + " is not closed), found " +
                                quote(t));
      }
      return error_at(at, "expected " + expected + " in joint " + quote(J().joint.name) + ", found " + quote(t));
    }
  }
  return Ok{};
}

Result<Motion> Parser::run() {
  if (auto s = read_header(); !s) return s.error();
  while (true) {
    const std::string_view t = peek_token();
    if (iequals(t, "ROOT")) {
      if (auto s = read_tree(); !s) return s.error();
    } else if (iequals(t, "MOTION") && !joints_.empty()) {
      auto m = read_motion();
      if (m.ok()) finish_warnings();
      return m;
    } else {
      next_token();
      return error_at(token_offset_, std::string(joints_.empty() ? "expected ROOT" : "expected ROOT or MOTION") +
                                         ", found " + quote(t));
    }
  }
}

Result<Motion> Parser::read_motion() {
  next_token();  // MOTION
  const std::size_t motion_offset = token_offset_;

  // "Frames: N" (the number may be glued to the colon or sit on the next token).
  std::string_view t = next_token();
  const std::size_t frames_offset = token_offset_;
  if (!istarts_with(t, "Frames:")) return error_at(token_offset_, "expected 'Frames:' after MOTION, found " + quote(t));
  std::string_view count_text = t.substr(7);
  std::size_t count_offset = token_offset_ + 7;
  if (count_text.empty()) {
    count_text = next_token();
    count_offset = token_offset_;
  }
  std::uint64_t declared = 0;
  if (auto s = read_count(count_text, count_offset, declared, "the frame count after 'Frames:'"); !s) return s.error();

  // "Frame Time: T", optional: some writers leave it out.
  double frame_time = 0.0;
  if (iequals(peek_token(), "Frame")) {
    next_token();
    t = next_token();
    if (!istarts_with(t, "Time:")) return error_at(token_offset_, "expected 'Frame Time:', found " + quote(t));
    if (t.size() > 5) {
      pos_ = token_offset_ + 5;  // the number is glued to the colon
    }
    if (auto s = read_number(frame_time, "the frame time (seconds) after 'Frame Time:'"); !s) return s.error();
    if (frame_time < 0)
      return error_at(token_offset_, "frame time must not be negative, found " +
                                         quote(text_.substr(token_offset_, pos_ - token_offset_)));
    if (frame_time == 0) warn_at(token_offset_, "Frame Time is 0: the frame rate is unknown (duration shows as 0)");
  } else {
    warn_at(pos_, "no 'Frame Time:' line after 'Frames:'; the frame rate is unknown (frame time set to 0)");
  }

  // Build the skeleton before reading values: it fixes the row stride.
  std::vector<Joint> joints;
  joints.reserve(joints_.size());
  for (const Pending& p : joints_) joints.push_back(p.joint);
  for (std::size_t j = 0; j < joints_.size(); ++j) {
    const Pending& p = joints_[j];
    if (p.soft_link.empty()) continue;
    const auto it = names_.find(p.soft_link);
    if (it == names_.end()) return error_at(p.soft_link_offset, "SOFTLINK names unknown joint " + quote(p.soft_link));
    if (it->second == static_cast<int>(j))
      return error_at(p.soft_link_offset, "a joint cannot be soft-linked to itself");
    joints[j].soft_parent = it->second;
  }
  auto skeleton = Skeleton::create(std::move(joints));
  if (!skeleton) return error_at(motion_offset, "invalid hierarchy: " + skeleton.error().message);

  Motion m;
  m.skeleton = std::move(skeleton).value();
  m.convention = dialect_ == Dialect::kBvh ? Convention::kPostRotation : Convention::kPreRotation;
  m.frame_time = frame_time;
  const std::size_t stride = m.stride();

  // The rows: a stream of numbers, `stride` per frame, wrapping across lines
  // allowed. Hot loop: no tokens, no line counting (locations are computed
  // from the byte offset only if something goes wrong).
  const char* const begin = text_.data();
  const char* const end = begin + text_.size();
  const char* p = begin + pos_;
  const std::size_t bytes_left = static_cast<std::size_t>(end - p);
  // Each value takes at least two bytes ("0 "): never reserve more than the
  // file can hold, whatever `Frames:` claims.
  const std::size_t max_values = bytes_left / 2 + 1;
  if (stride == 0) {
    while (p < end && is_space(*p)) ++p;
    if (p < end)
      return error_at(static_cast<std::size_t>(p - begin),
                      "unexpected value after 'Frame Time:': the hierarchy has no channels");
    // Without channels the frame count cannot be checked against the data: capped (gmr/core/limits.h).
    if (auto s = check_frame_count(declared, 0); !s.ok()) return error_at(count_offset, s.error().message);
    m.frame_count = static_cast<std::size_t>(declared);
    return m;
  }
  std::vector<double>& values = m.values;
  values.resize(declared <= max_values / stride ? static_cast<std::size_t>(declared) * stride : max_values);
  std::size_t n = 0;
  const char* frame_start = p;  // first value of the frame being read
  std::size_t left_in_frame = stride;
  while (true) {
    while (p < end && is_space(*p)) ++p;
    if (p == end) break;
    if (n == values.size())
      values.resize(std::min(std::max<std::size_t>(values.size() * 2, 1024), max_values + stride));
    double v;
    const char* e = read_double(p, end, v);
    if (e == nullptr) {
      const char* q = p;
      while (q < end && !is_space(*q)) ++q;
      return error_at(static_cast<std::size_t>(p - begin),
                      "expected a number (value " + std::to_string(n % stride + 1) + " of " + std::to_string(stride) +
                          " in frame " + std::to_string(n / stride) + "), found " +
                          quote(std::string_view(p, static_cast<std::size_t>(q - p))));
    }
    if (e < end && !is_space(*e)) {
      const char* q = e;
      while (q < end && !is_space(*q)) ++q;
      return error_at(static_cast<std::size_t>(e - begin),
                      "malformed number " + quote(std::string_view(p, static_cast<std::size_t>(q - p))) +
                          ": expected whitespace after " + quote(std::string_view(p, static_cast<std::size_t>(e - p))) +
                          " (numbers run together?)");
    }
    if (!std::isfinite(v)) {
      return error_at(static_cast<std::size_t>(p - begin),
                      "value " + quote(std::string_view(p, static_cast<std::size_t>(e - p))) + " is not finite");
    }
    if (left_in_frame == stride) frame_start = p;
    if (--left_in_frame == 0) left_in_frame = stride;
    values[n++] = v;
    p = e;
  }

  const std::size_t frames = n / stride;
  const std::size_t partial = n % stride;
  if (auto s = check_frame_count(frames, stride); !s.ok()) {
    return error_at(frames_offset, "the file holds " + std::to_string(frames) + " frames: " + s.error().message);
  }
  if (partial != 0) {
    return error_at(static_cast<std::size_t>(end - begin),
                    "file ends in frame " + std::to_string(frames) + " (counting from 0, starting at line " +
                        std::to_string(line_of(static_cast<std::size_t>(frame_start - begin))) + ") after " +
                        std::to_string(partial) + " of its " + std::to_string(stride) +
                        " values: the file is truncated or a row is short");
  }
  if (frames == 0 && declared > 0) {
    return error_at(static_cast<std::size_t>(end - begin), "no frame data: 'Frames: " + std::to_string(declared) +
                                                               "' declared but the file ends after the " +
                                                               "'Frame Time:' line (truncated file?)");
  }
  if (frames != declared) {
    warn_at(frames_offset, "'Frames: " + std::to_string(declared) + "' but the file holds " + std::to_string(frames) +
                               " complete frames of " + std::to_string(stride) + " values; loaded all " +
                               std::to_string(frames));
  }
  values.resize(n);
  values.shrink_to_fit();
  m.frame_count = frames;

  // Rows list channels in the order their CHANNELS lines appear. That differs
  // from joint order only when a CHANNELS line follows a child JOINT block:
  // reorder the columns then.
  if (!std::is_sorted(channel_decl_order_.begin(), channel_decl_order_.end())) {
    std::vector<std::size_t> column_to_slot;
    column_to_slot.reserve(stride);
    for (int j : channel_decl_order_) {
      const auto off = static_cast<std::size_t>(m.skeleton.channel_offset(j));
      for (std::size_t c = 0; c < m.skeleton.joint(j).channels.size(); ++c) column_to_slot.push_back(off + c);
    }
    std::vector<double> row(stride);
    for (std::size_t f = 0; f < frames; ++f) {
      const auto fr = m.frame(f);
      for (std::size_t c = 0; c < stride; ++c) row[column_to_slot[c]] = fr[c];
      std::copy(row.begin(), row.end(), fr.begin());
    }
  }
  return m;
}

// --- writer

void append_double(std::string& out, double v) {
  char buf[32];
  out.append(buf, format_shortest(buf, v));
}

void indent(std::string& out, int depth) { out.append(static_cast<std::size_t>(depth), '\t'); }

// A name the reader gives back unchanged: no control character but tab, no
// surrounding space, not ending in '{' (that would read as the block's brace).
Status check_name(std::string_view name) {
  const bool ok = !name.empty() && !is_space(name.front()) && !is_space(name.back()) && name.back() != '{' &&
                  control_char(name) == std::string_view::npos;
  if (!ok)
    return make_error("joint name " + quote(name) +
                      " cannot be written: names must be non-empty, on one line, "
                      "without leading or trailing space, and must not end in '{'");
  return Ok{};
}

}  // namespace

std::vector<int> depth_first_order(const Skeleton& skeleton) {
  std::vector<int> order;
  order.reserve(skeleton.size());
  std::vector<int> stack;
  for (int r : skeleton.roots()) {
    stack.push_back(r);
    while (!stack.empty()) {
      const int j = stack.back();
      stack.pop_back();
      order.push_back(j);
      const auto ch = skeleton.children(j);
      for (auto it = ch.rbegin(); it != ch.rend(); ++it) stack.push_back(*it);
    }
  }
  return order;
}

Result<Motion> parse_hierarchy_text(std::string_view text, std::string_view file_label, Dialect dialect,
                                    Warnings* out_warnings) {
  return Parser(text, file_label, dialect, out_warnings).run();
}

Result<std::string> format_hierarchy_text(const Motion& motion, Dialect dialect) {
  const bool bvh = dialect == Dialect::kBvh;
  if (bvh && motion.convention != Convention::kPostRotation)
    return make_error("BVH needs a post-rotation motion; this one is pre-rotation (GMR): convert it first");
  if (!bvh && motion.convention != Convention::kPreRotation)
    return make_error("GMR needs a pre-rotation motion; this one is post-rotation (BVH): convert it first");
  if (motion.skeleton.empty()) return make_error("cannot write a motion with no joints");
  if (auto s = motion.validate(); !s) return s.error();
  const Skeleton& sk = motion.skeleton;
  for (const Joint& j : sk.joints()) {
    if (auto s = check_name(j.name); !s) return s.error();
  }

  const std::vector<int> order = depth_first_order(sk);
  std::string out;
  out.reserve(4096 + motion.values.size() * 12);
  if (!bvh) out += "GMR " + std::to_string(kGmrFormatVersion) + "\n";
  out += "HIERARCHY\n";

  // Names seen so far, to know which End Site names the reader would make up.
  std::unordered_set<std::string_view> seen;
  std::vector<int> next_end_site(sk.size(), 1);
  std::vector<int> open;  // joints whose block is open, innermost last
  auto close_until = [&](int parent) {
    while (!open.empty() && open.back() != parent) {
      open.pop_back();
      indent(out, static_cast<int>(open.size()));
      out += "}\n";
    }
  };
  for (int j : order) {
    const Joint& joint = sk.joint(j);
    close_until(joint.parent);
    const int depth = static_cast<int>(open.size());
    // A leaf without channels is an End Site when the reader would give it
    // this very name; any other name stays on a JOINT with CHANNELS 0 (an
    // `End Site <name>` line is not standard BVH and other readers drop it).
    bool end_site = false;
    if (bvh && joint.parent != kNoParent && joint.channels.empty() && sk.children(j).empty()) {
      int& next = next_end_site[static_cast<std::size_t>(joint.parent)];
      int k = next;
      const std::string def = default_end_site_name(
          sk.joint(joint.parent).name, [&](const std::string& n) { return seen.count(n) != 0; }, k);
      // The reader advances its counter only for unnamed End Sites: do the same.
      if (joint.name == def) {
        end_site = true;
        next = k;
      }
    }
    indent(out, depth);
    if (joint.parent == kNoParent) {
      out += "ROOT ";
      out += joint.name;
    } else if (end_site) {
      out += "End Site";
    } else {
      out += "JOINT ";
      out += joint.name;
    }
    seen.insert(joint.name);
    out += '\n';
    indent(out, depth);
    out += "{\n";
    if (!bvh && joint.soft_parent != kNoParent) {
      indent(out, depth + 1);
      out += "SOFTLINK ";
      out += sk.joint(joint.soft_parent).name;
      out += '\n';
    }
    indent(out, depth + 1);
    out += "OFFSET";
    for (int i = 0; i < 3; ++i) {
      out += ' ';
      append_double(out, joint.offset[i]);
    }
    out += '\n';
    if (!end_site) {
      indent(out, depth + 1);
      out += "CHANNELS ";
      out += std::to_string(joint.channels.size());
      for (ChannelType c : joint.channels) {
        out += ' ';
        out += channel_name(c);
      }
      out += '\n';
    }
    open.push_back(j);
  }
  close_until(kNoParent);

  out += "MOTION\nFrames: ";
  out += std::to_string(motion.frame_count);
  out += "\nFrame Time: ";
  append_double(out, motion.frame_time);
  out += '\n';

  // Columns follow the written (depth-first) joint order.
  std::vector<std::size_t> columns;
  columns.reserve(motion.stride());
  for (int j : order) {
    const auto off = static_cast<std::size_t>(sk.channel_offset(j));
    for (std::size_t c = 0; c < sk.joint(j).channels.size(); ++c) columns.push_back(off + c);
  }
  // One row at a time into a local buffer (a shortest double is at most 24
  // characters; format_shortest wants 32 bytes), then one append: the row
  // loop is the writer's hot path.
  std::vector<char> line(columns.size() * 25 + 32);
  for (std::size_t f = 0; f < motion.frame_count; ++f) {
    const auto row = motion.frame(f);
    char* p = line.data();
    for (std::size_t c = 0; c < columns.size(); ++c) {
      p = format_shortest(p, row[columns[c]]);
      *p++ = ' ';
    }
    if (p != line.data()) --p;  // no trailing space
    *p++ = '\n';
    out.append(line.data(), static_cast<std::size_t>(p - line.data()));
  }
  return out;
}

Result<Motion> read_hierarchy_file(const std::filesystem::path& path, Dialect dialect, Warnings* out_warnings) {
  auto text = read_file(path);
  if (!text) return text.error();
  return parse_hierarchy_text(*text, path.string(), dialect, out_warnings);
}

Status write_hierarchy_file(const Motion& motion, Dialect dialect, const std::filesystem::path& path) {
  auto text = format_hierarchy_text(motion, dialect);
  if (!text) {
    Error e = text.error();
    if (e.file.empty()) e.file = path.string();
    return e;
  }
  return write_file_atomic(path, *text);
}

}  // namespace gmr::detail
