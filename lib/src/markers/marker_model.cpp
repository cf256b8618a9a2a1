// The marker skeleton model: the text format's parser and the built-in models.
#include "gmr/markers/marker_model.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <optional>
#include <set>

#include "gmr/core/file_util.h"

namespace gmr {
namespace {

// The CMU 41-marker Vicon set. Joints are named like the bones of CMU's ASF
// skeletons and sit where those bones end; the constants place them where
// CMU's own skeletons have them (set on take 01_01 against 01.asf; the
// figures are in docs/markers.md). Functional centres (hips, knees, ankles,
// shoulders, elbows, lumbar and neck) take what the take does not determine
// from their priors; knees, ankles and elbows are hinges, which take only
// their best-determined direction from the take:
// - hips: 0.36, 0.05 and 0.435 of the width between the front waist markers
//   medial, posterior and inferior of their midpoint (lengths in
//   half-widths). Bell and Harrington's regression from the ASIS says 0.36,
//   0.19, 0.30; CMU's front waist markers sit higher and further back;
// - knees 90 mm medial of the lateral marker (toward the other knee); ankles
//   48 mm and elbows 63 mm deep of theirs, in the limb segment's own frame:
//   x up the segment (toward the knee, the shoulder), y across it toward the
//   shin or upper-arm marker, z = x cross y (so z flips between the sides).
//   A direction toward the other side's twin swings with every step and arm
//   swing, and its median over a short walk falls short (02_01's ankles sat
//   7-16 mm across the shank from the marker). CMU's centres are deeper
//   than half a joint width plus a marker radius (60, 42, 40 mm);
// - knees: then slid along the thigh (`split`) to 0.499 of the leg, hip to
//   knee to ankle: the thigh 0.245 and the leg 0.246 of the body's height
//   (Winter, after Drillis and Contini). Where LKNE sits on the knee varies
//   between subjects (CMU's knee 15 mm below it on subject 01, 24 mm above
//   on 02) and the take cannot tell: walking flexes the knee too little for
//   the sweep to fix the coordinate along the bone;
// - shoulders: 65 mm below the acromion marker, down the thorax;
// - wrists: from the midpoint of the wrist-bar markers, 0.3 of the way to the
//   elbow and 40 mm to the palm side (the bar sits on the back of the wrist):
//   x = toward the elbow, z = x cross (toward the ulnar marker), so +z is
//   palmar on the left arm and dorsal on the right.
// Feet are the midpoint of the toe and fifth-metatarsal markers, the head
// the centre of the four head markers.
constexpr std::string_view kCmu41 = R"(gmr-marker-model 1
name cmu41
outlier 40mm
min-spread 15mm
min-relative-spread 0.3

part pelvis LFWT RFWT LBWT RBWT
part thorax lowerback C7 T10 CLAV STRN RBAC
part head upperneck LFHD RFHD LBHD RBHD
part lthigh lhipjoint LTHI LKNE
part lshank lfemur LSHN LANK
part lfoot ltibia LHEE LTOE LMT5
part rthigh rhipjoint RTHI RKNE
part rshank rfemur RSHN RANK
part rfoot rtibia RHEE RTOE RMT5
part lshoulder thorax LSHO
part lupperarm lclavicle LUPA LELB
part lforearm lhumerus LFRM LWRA LWRB
part lhand lradius LFIN
part rshoulder thorax RSHO
part rupperarm rclavicle RUPA RELB
part rforearm rhumerus RFRM RWRA RWRB
part rhand rradius RFIN

joint root in pelvis at mean(LFWT, RFWT, LBWT, RBWT)
joint lhipjoint parent root in pelvis centre lthigh prior local(mean(LFWT, RFWT), LFWT, mean(LBWT, RBWT), 0.72, 0.1, -0.87)
joint lfemur parent lhipjoint in lthigh centre lshank hinge prior along(LKNE, LKNE, RKNE, 90mm) split ltibia 0.499
joint ltibia parent lfemur in lshank centre lfoot hinge prior local(LANK, lfemur, LSHN, -3mm, -42mm, 23mm)
joint lfoot parent ltibia in lfoot at mean(LTOE, LMT5)
joint rhipjoint parent root in pelvis centre rthigh prior local(mean(LFWT, RFWT), RFWT, mean(LBWT, RBWT), 0.72, 0.1, 0.87)
joint rfemur parent rhipjoint in rthigh centre rshank hinge prior along(RKNE, RKNE, LKNE, 90mm) split rtibia 0.499
joint rtibia parent rfemur in rshank centre rfoot hinge prior local(RANK, rfemur, RSHN, -3mm, -42mm, -23mm)
joint rfoot parent rtibia in rfoot at mean(RTOE, RMT5)
joint lowerback parent root in pelvis centre thorax prior along(mean(LBWT, RBWT), mean(LBWT, RBWT), T10, 0.3)
joint thorax parent lowerback in thorax at mean(C7, CLAV)
joint upperneck parent thorax in thorax centre head prior along(mean(C7, CLAV), mean(C7, CLAV), mean(LFHD, RFHD, LBHD, RBHD), 0.5)
joint head parent upperneck in head at mean(LFHD, RFHD, LBHD, RBHD)
joint lclavicle parent thorax in lshoulder centre lupperarm prior along(LSHO, mean(C7, CLAV), mean(T10, STRN), 65mm)
joint lhumerus parent lclavicle in lupperarm centre lforearm hinge prior local(LELB, lclavicle, LUPA, 12mm, -55mm, 30mm)
joint lradius parent lhumerus in lforearm at local(mean(LWRA, LWRB), lhumerus, LWRB, 0.3, 0, 40mm)
joint lhand parent lradius in lhand at LFIN
joint rclavicle parent thorax in rshoulder centre rupperarm prior along(RSHO, mean(C7, CLAV), mean(T10, STRN), 65mm)
joint rhumerus parent rclavicle in rupperarm centre rforearm hinge prior local(RELB, rclavicle, RUPA, 12mm, -55mm, -30mm)
joint rradius parent rhumerus in rforearm at local(mean(RWRA, RWRB), rhumerus, RWRB, 0.3, 0, -40mm)
joint rhand parent rradius in rhand at RFIN
)";

struct Builtin {
  std::string_view name;
  std::string_view text;
};
constexpr Builtin kBuiltins[] = {{"cmu41", kCmu41}};

// "cmu41, ...": for messages.
std::string builtin_list() {
  std::string known;
  for (const Builtin& b : kBuiltins) known += (known.empty() ? "" : ", ") + std::string(b.name);
  return known;
}

// ---- tokens of one line

struct Token {
  enum Kind { kWord, kNumber, kPunct, kEnd } kind = kEnd;
  std::string_view text;
  int column = 0;
};

bool word_char(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.' || c == ':' || c == '+';
}

class Parser {
 public:
  Parser(std::string_view text, std::string_view label) : text_(text), label_(label) {}

  Result<MarkerModel> run();

 private:
  Error error_at(int column, std::string message) const {
    Error e;
    e.file = std::string(label_);
    e.line = line_no_;
    e.column = column;
    e.message = std::move(message);
    return e;
  }
  Error error_here(std::string message) const { return error_at(peek().column, std::move(message)); }

  void tokenize(std::string_view line);
  const Token& peek() const { return tokens_[pos_]; }
  Token next() { return pos_ + 1 < tokens_.size() ? tokens_[pos_++] : tokens_[pos_]; }
  bool at_end() const { return peek().kind == Token::kEnd; }
  bool accept(std::string_view punct) {
    if (peek().kind == Token::kPunct && peek().text == punct) {
      ++pos_;
      return true;
    }
    return false;
  }

  Result<std::string> word(std::string_view what);
  Result<double> number(std::string_view what);
  // The name a `part` or `joint` statement defines; `taken`: the model has
  // one of that kind and name already.
  Result<std::string> new_name(const std::string& kind, bool taken) {
    const int column = tokens_[0].column;
    auto n = word("the " + kind + "'s name");
    if (n && taken) return error_at(column, kind + " '" + *n + "' is defined twice");
    return n;
  }
  // A length: NUMBER with mm, cm or m (absolute, returned in mm), or a bare
  // NUMBER (relative) when relative_ok.
  Status length(double& value, bool& absolute, bool relative_ok, std::string_view what);
  Result<PointExpr> expr();
  Status statement(MarkerModel& model);
  Status check(MarkerModel& model);

  std::string_view text_;
  std::string_view label_;
  int line_no_ = 0;
  std::vector<Token> tokens_;
  std::size_t pos_ = 0;
  bool header_seen_ = false;
  std::string builtin_;
};

void Parser::tokenize(std::string_view line) {
  tokens_.clear();
  pos_ = 0;
  std::size_t i = 0;
  while (i < line.size()) {
    const char c = line[i];
    if (c == '#') break;
    if (c == ' ' || c == '\t' || c == '\r') {
      ++i;
      continue;
    }
    Token t;
    t.column = static_cast<int>(i) + 1;
    if (c == '(' || c == ')' || c == ',' || c == '*') {
      t.kind = Token::kPunct;
      t.text = line.substr(i, 1);
      ++i;
    } else {
      std::size_t j = i;
      while (j < line.size() && word_char(line[j])) ++j;
      if (j == i) j = i + 1;  // an unexpected character: its own token, refused by the grammar
      t.text = line.substr(i, j - i);
      const char f = t.text[0];
      t.kind = (std::isdigit(static_cast<unsigned char>(f)) || f == '-' || f == '+' || f == '.') ? Token::kNumber
                                                                                                 : Token::kWord;
      if (!word_char(c)) t.kind = Token::kPunct;
      i = j;
    }
    tokens_.push_back(t);
  }
  Token end;
  end.column = static_cast<int>(line.size()) + 1;
  tokens_.push_back(end);
}

Result<std::string> Parser::word(std::string_view what) {
  if (peek().kind != Token::kWord) {
    return error_here(
        "expected " + std::string(what) +
        (at_end() ? std::string(" at the end of the line") : ", found '" + std::string(peek().text) + "'"));
  }
  return std::string(next().text);
}

// A number token's value and what follows the digits (a unit); nullopt when
// it does not start with a finite number. A leading '+' is allowed.
std::optional<std::string_view> read_number(std::string_view s, double& v) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || !std::isfinite(v)) return std::nullopt;
  return s.substr(static_cast<std::size_t>(p - s.data()));
}

Result<double> Parser::number(std::string_view what) {
  if (peek().kind != Token::kNumber) return error_here("expected " + std::string(what));
  const Token t = next();
  double v = 0;
  const auto rest = read_number(t.text, v);
  if (!rest || !rest->empty()) {
    return error_at(t.column, "'" + std::string(t.text) + "' is not a number (" + std::string(what) + ")");
  }
  return v;
}

Status Parser::length(double& value, bool& absolute, bool relative_ok, std::string_view what) {
  if (peek().kind != Token::kNumber) return error_here("expected " + std::string(what));
  const Token t = next();
  double v = 0;
  const auto rest = read_number(t.text, v);
  if (!rest) return error_at(t.column, "'" + std::string(t.text) + "' is not a length (" + std::string(what) + ")");
  const std::string_view unit = *rest;
  absolute = true;
  if (unit == "mm") {
    value = v;
  } else if (unit == "cm") {
    value = v * 10;
  } else if (unit == "m") {
    value = v * 1000;
  } else if (unit.empty() && relative_ok) {
    value = v;
    absolute = false;
  } else {
    return error_at(
        t.column, "'" + std::string(t.text) + "': " + std::string(what) +
                      (relative_ok ? " takes a number, or a length in mm, cm or m" : " takes a length in mm, cm or m"));
  }
  return Ok{};
}

Result<PointExpr> Parser::expr() {
  const int column = peek().column;
  auto name = word("a marker, a joint, mean(...), along(...) or local(...)");
  if (!name) return name.error();
  PointExpr e;
  const std::string& n = *name;
  if (n != "mean" && n != "along" && n != "local") {
    e.kind = PointExpr::Kind::kMarker;  // a joint when the model has one of this name (resolved in check())
    e.name = n;
    return e;
  }
  if (!accept("(")) return error_here("expected '(' after " + n);
  e.kind = n == "mean" ? PointExpr::Kind::kMean : n == "along" ? PointExpr::Kind::kAlong : PointExpr::Kind::kLocal;
  const std::size_t points = e.kind == PointExpr::Kind::kMean ? 0 : 3;
  const std::size_t lengths = e.kind == PointExpr::Kind::kAlong ? 1 : e.kind == PointExpr::Kind::kLocal ? 3 : 0;
  for (;;) {
    if (points != 0 && e.args.size() == points) break;
    auto a = expr();
    if (!a) return a.error();
    e.args.push_back(std::move(*a));
    if (accept(",")) continue;
    if (points == 0 && accept(")")) return e;
    return error_here(points == 0 ? "expected ',' or ')' in mean(...)"
                                  : n + "(...) takes 3 points then " + std::to_string(lengths) +
                                        (lengths == 1 ? " length" : " lengths"));
  }
  for (std::size_t k = 0; k < lengths; ++k) {
    if (auto s = length(e.lengths[k], e.absolute[k], true, n + "'s length"); !s) return s.error();
    if (k + 1 < lengths && !accept(",")) return error_here("expected ',' between " + n + "'s lengths");
  }
  if (!accept(")")) return error_at(column, n + "(...) is not closed: expected ')'");
  return e;
}

Status Parser::statement(MarkerModel& model) {
  const Token first = peek();
  auto key = word("a statement (part, joint, name, outlier, ...)");
  if (!key) return key.error();
  if (*key == "gmr-marker-model") {
    auto v = number("the format version");
    if (!v) return v.error();
    if (*v != 1)
      return error_at(first.column, "unsupported model format version " + std::string(tokens_[1].text) +
                                        " (this build reads version 1)");
    header_seen_ = true;
  } else if (*key == "builtin") {
    auto n = word("a built-in model name");
    if (!n) return n.error();
    builtin_ = *n;
  } else if (!header_seen_) {
    return error_at(first.column, "expected 'gmr-marker-model 1' (or 'builtin NAME') before '" + *key + "'");
  } else if (*key == "name") {
    auto n = word("the model's name");
    if (!n) return n.error();
    model.name = *n;
  } else if (*key == "outlier" || *key == "min-spread") {
    double v = 0;
    bool absolute = true;
    if (auto s = length(v, absolute, false, *key); !s) return s.error();
    if (!(v > 0)) return error_at(first.column, *key + " must be positive");
    (*key == "outlier" ? model.outlier_mm : model.min_spread_mm) = v;
  } else if (*key == "min-relative-spread") {
    auto v = number("a fraction");
    if (!v) return v.error();
    if (!(*v >= 0 && *v < 1)) return error_at(first.column, "min-relative-spread must be in [0, 1)");
    model.min_relative_spread = *v;
  } else if (*key == "part") {
    ModelPart p;
    p.line = line_no_;
    auto n = new_name("part", model.find_part(peek().text) >= 0);
    if (!n) return n.error();
    p.name = *n;
    while (!at_end()) {
      auto point = word("a marker or joint name");
      if (!point) return point.error();
      double w = 1;
      if (accept("*")) {
        auto v = number("a weight");
        if (!v) return v.error();
        if (!(*v > 0)) return error_here("a weight must be positive");
        w = *v;
      }
      if (std::find(p.points.begin(), p.points.end(), *point) != p.points.end()) {
        return error_here("part '" + p.name + "' lists '" + *point + "' twice");
      }
      p.points.push_back(*point);
      p.weights.push_back(w);
    }
    if (p.points.size() < 2) return error_at(first.column, "part '" + p.name + "' needs at least 2 points");
    model.parts.push_back(std::move(p));
  } else if (*key == "joint") {
    ModelJoint j;
    j.line = line_no_;
    auto n = new_name("joint", model.find_joint(peek().text) >= 0);
    if (!n) return n.error();
    j.name = *n;
    auto k = word("'parent' or 'in'");
    if (!k) return k.error();
    if (*k == "parent") {
      auto parent = word("the parent joint");
      if (!parent) return parent.error();
      j.parent = model.find_joint(*parent);
      if (j.parent < 0)
        return error_at(first.column,
                        "joint '" + j.name + "': parent '" + *parent + "' is not a joint defined above it");
      k = word("'in'");
      if (!k) return k.error();
    }
    if (*k != "in") return error_at(first.column, "joint '" + j.name + "': expected 'in PART', found '" + *k + "'");
    auto part = word("the part the joint is fixed in");
    if (!part) return part.error();
    j.part = model.find_part(*part);
    if (j.part < 0) return error_at(first.column, "joint '" + j.name + "': unknown part '" + *part + "'");
    auto rule = word("'at' or 'centre'");
    if (!rule) return rule.error();
    if (*rule == "at") {
      j.rule = ModelJoint::Rule::kAt;
    } else if (*rule == "centre" || *rule == "center") {
      j.rule = ModelJoint::Rule::kCentre;
      auto child = word("the part on the joint's other side");
      if (!child) return child.error();
      j.child_part = model.find_part(*child);
      if (j.child_part < 0) return error_at(first.column, "joint '" + j.name + "': unknown part '" + *child + "'");
      if (j.child_part == j.part)
        return error_at(first.column, "joint '" + j.name + "': centre of '" + *child + "' within the same part");
      auto p = word("'prior' or 'hinge'");
      if (!p) return p.error();
      if (*p == "hinge") {
        j.hinge = true;
        p = word("'prior'");
        if (!p) return p.error();
      }
      if (*p != "prior") {
        return error_at(first.column, "joint '" + j.name + "': expected '[hinge] prior EXPR' after the part");
      }
    } else {
      return error_at(first.column,
                      "joint '" + j.name + "': expected 'at EXPR' or 'centre PART prior EXPR', found '" + *rule + "'");
    }
    auto e = expr();
    if (!e) return e.error();
    j.where = std::move(*e);
    if (peek().kind == Token::kWord && peek().text == "split") {
      next();
      // The end joint is defined below this one: check() resolves it.
      auto end = word("the joint at the chain's end ('split END FRACTION')");
      if (!end) return end.error();
      j.split_name = *end;
      const int column = peek().column;
      auto fraction = number("the fraction of the chain's length ('split END FRACTION')");
      if (!fraction) return fraction.error();
      if (!(*fraction > 0 && *fraction < 1)) return error_at(column, "a split's fraction must be between 0 and 1");
      j.split_fraction = *fraction;
    }
    model.joints.push_back(std::move(j));
  } else {
    return error_at(first.column, "unknown statement '" + *key + "'");
  }
  if (!at_end()) return error_here("unexpected '" + std::string(peek().text) + "' at the end of the statement");
  return Ok{};
}

// Joint references in an expression: names that are joints become kJoint and
// must come before `limit` (a joint's own index, or the joint count).
Status resolve(PointExpr& e, const MarkerModel& model, int limit, const std::string& where, std::string_view label,
               int line) {
  if (e.kind == PointExpr::Kind::kMarker) {
    const int j = model.find_joint(e.name);
    if (j >= 0) {
      if (j >= limit) {
        Error err;
        err.file = std::string(label);
        err.line = line;
        err.message = where + " uses joint '" + e.name + "' before it is found (define it above)";
        return err;
      }
      e.kind = PointExpr::Kind::kJoint;
    }
    return Ok{};
  }
  for (PointExpr& a : e.args) {
    if (auto s = resolve(a, model, limit, where, label, line); !s) return s;
  }
  return Ok{};
}

Status Parser::check(MarkerModel& model) {
  auto fail = [&](int line, std::string message) {
    Error e;
    e.file = std::string(label_);
    e.line = line;
    e.message = std::move(message);
    return e;
  };
  if (model.joints.empty()) return fail(line_no_, "the model has no joint");
  const int n = static_cast<int>(model.joints.size());
  for (ModelPart& p : model.parts) {
    p.point_is_joint.assign(p.points.size(), false);
    for (std::size_t k = 0; k < p.points.size(); ++k) p.point_is_joint[k] = model.find_joint(p.points[k]) >= 0;
    const std::size_t markers =
        static_cast<std::size_t>(std::count(p.point_is_joint.begin(), p.point_is_joint.end(), false));
    if (markers == 0) return fail(p.line, "part '" + p.name + "' has no marker");
    if (p.points.size() == 2 && !p.point_is_joint[0]) {
      return fail(p.line, "part '" + p.name +
                              "' has 2 points: the first must be a joint (its twist comes from that "
                              "joint's part)");
    }
  }
  for (int k = 0; k < n; ++k) {
    ModelJoint& j = model.joints[static_cast<std::size_t>(k)];
    const std::string where = "joint '" + j.name + "'";
    if (auto s = resolve(j.where, model, k, where, label_, j.line); !s) return s;
    // Its part is fitted before it is placed: the part's joints come first.
    const ModelPart& p = model.parts[static_cast<std::size_t>(j.part)];
    for (std::size_t q = 0; q < p.points.size(); ++q) {
      if (p.point_is_joint[q] && model.find_joint(p.points[q]) >= k) {
        return fail(j.line, where + " is fixed in part '" + p.name + "', which uses joint '" + p.points[q] +
                                "': that joint must be defined above");
      }
    }
    if (!j.split_name.empty()) {
      j.split = model.find_joint(j.split_name);
      int up = j.split;
      while (up > k) up = model.joints[static_cast<std::size_t>(up)].parent;
      if (j.split < 0 || up != k || j.parent < 0) {
        return fail(j.line, where + " splits the chain from its parent to '" + j.split_name +
                                "': that must be a joint below it in the tree" +
                                (j.parent < 0 ? std::string(", and the joint needs a parent") : std::string()));
      }
    }
    if (p.points.size() == 2) {
      const int first = model.find_joint(p.points[0]);
      if (model.joints[static_cast<std::size_t>(first)].part == j.part) {
        return fail(p.line,
                    "part '" + p.name + "': its first point '" + p.points[0] + "' must be fixed in another part");
      }
    }
  }
  return Ok{};
}

Result<MarkerModel> Parser::run() {
  MarkerModel model;
  std::size_t begin = 0;
  while (begin <= text_.size()) {
    std::size_t end = text_.find('\n', begin);
    if (end == std::string_view::npos) end = text_.size();
    ++line_no_;
    tokenize(text_.substr(begin, end - begin));
    if (!at_end()) {
      if (!builtin_.empty()) return error_here("'builtin " + builtin_ + "' must be the model's only statement");
      if (auto s = statement(model); !s) return s.error();
      if (!builtin_.empty() && header_seen_) return error_at(1, "'builtin' must be the model's only statement");
    }
    begin = end + 1;
  }
  if (!builtin_.empty()) {
    auto m = builtin_marker_model(builtin_);
    if (!m) {
      Error e = m.error();
      e.file = std::string(label_);
      return e;
    }
    return m;
  }
  if (!header_seen_) {
    Error e;
    e.file = std::string(label_);
    e.message = "not a marker model: expected 'gmr-marker-model 1' or 'builtin NAME'";
    return e;
  }
  if (auto s = check(model); !s) return s.error();
  return model;
}

void collect_markers(const PointExpr& e, std::vector<std::string>& out, std::set<std::string>& seen) {
  if (e.kind == PointExpr::Kind::kMarker && seen.insert(e.name).second) out.push_back(e.name);
  for (const PointExpr& a : e.args) collect_markers(a, out, seen);
}

}  // namespace

int MarkerModel::find_part(std::string_view n) const {
  for (std::size_t i = 0; i < parts.size(); ++i) {
    if (parts[i].name == n) return static_cast<int>(i);
  }
  return -1;
}

int MarkerModel::find_joint(std::string_view n) const {
  for (std::size_t i = 0; i < joints.size(); ++i) {
    if (joints[i].name == n) return static_cast<int>(i);
  }
  return -1;
}

std::vector<std::string> MarkerModel::marker_names() const {
  std::vector<std::string> out;
  std::set<std::string> seen;
  for (const ModelPart& p : parts) {
    for (std::size_t k = 0; k < p.points.size(); ++k) {
      if (!(k < p.point_is_joint.size() && p.point_is_joint[k]) && seen.insert(p.points[k]).second) {
        out.push_back(p.points[k]);
      }
    }
  }
  for (const ModelJoint& j : joints) collect_markers(j.where, out, seen);
  return out;
}

Result<MarkerModel> parse_marker_model(std::string_view text, std::string_view label) {
  return Parser(text, label).run();
}

Result<MarkerModel> read_marker_model(const std::filesystem::path& path) {
  auto text = read_file(path);
  if (!text) return text.error();
  return parse_marker_model(*text, path.string());
}

std::vector<std::string> builtin_marker_model_names() {
  std::vector<std::string> names;
  for (const Builtin& b : kBuiltins) names.emplace_back(b.name);
  return names;
}

Result<std::string> builtin_marker_model_text(std::string_view name) {
  for (const Builtin& b : kBuiltins) {
    if (b.name == name) return std::string(b.text);
  }
  return make_error(ErrorKind::kNotFound,
                    "no built-in marker model '" + std::string(name) + "' (built in: " + builtin_list() + ")");
}

Result<MarkerModel> builtin_marker_model(std::string_view name) {
  auto text = builtin_marker_model_text(name);
  if (!text) return text.error();
  return parse_marker_model(*text, "<builtin " + std::string(name) + ">");
}

Result<MarkerModel> find_marker_model(std::string_view name_or_path) {
  for (const Builtin& b : kBuiltins) {
    if (b.name == name_or_path) return builtin_marker_model(name_or_path);
  }
  const std::filesystem::path path(name_or_path);
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return make_error(ErrorKind::kNotFound, "'" + std::string(name_or_path) + "' is neither a built-in marker model (" +
                                                builtin_list() + ") nor a file");
  }
  return read_marker_model(path);
}

std::string_view strip_subject_prefix(std::string_view marker_name) {
  const std::size_t colon = marker_name.rfind(':');
  return colon == std::string_view::npos ? marker_name : marker_name.substr(colon + 1);
}

}  // namespace gmr
