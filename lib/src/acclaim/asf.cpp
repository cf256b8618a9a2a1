// ASF reader: sections, keywords and fields in any order, one keyword per line
// (limits continue on the following lines).
#include <algorithm>
#include <unordered_map>

#include "acclaim_text.h"
#include "gmr/acclaim/asf.h"
#include "gmr/core/file_util.h"

namespace gmr {

using acclaim_detail::error_at;
using acclaim_detail::iequals;
using acclaim_detail::Line;
using acclaim_detail::LineReader;
using acclaim_detail::parse_integer;
using acclaim_detail::parse_number;
using acclaim_detail::put;
using acclaim_detail::put3;
using acclaim_detail::put_order;
using acclaim_detail::quote_text;
using acclaim_detail::to_lower;
using acclaim_detail::Token;

std::string_view acclaim_dof_name(AcclaimDof dof) {
  switch (dof) {
    case AcclaimDof::kRx:
      return "rx";
    case AcclaimDof::kRy:
      return "ry";
    case AcclaimDof::kRz:
      return "rz";
    case AcclaimDof::kTx:
      return "tx";
    case AcclaimDof::kTy:
      return "ty";
    case AcclaimDof::kTz:
      return "tz";
    case AcclaimDof::kL:
      return "l";
  }
  return "?";
}

int AsfSkeleton::find(std::string_view bone_name) const {
  for (std::size_t i = 0; i < bones.size(); ++i) {
    if (iequals(bones[i].name, bone_name)) return static_cast<int>(i);
  }
  return -1;
}

int AsfSkeleton::value_count() const {
  int n = 0;
  for (const AsfBone& b : bones) n += static_cast<int>(b.dofs.size());
  return n;
}

int AsfSkeleton::value_offset(int b) const {
  int n = 0;
  for (int i = 0; i < b; ++i) n += static_cast<int>(bones[static_cast<std::size_t>(i)].dofs.size());
  return n;
}

namespace {

enum class Section { kNone, kVersion, kName, kUnits, kDocumentation, kRoot, kBoneData, kHierarchy, kUnknown };

std::optional<AcclaimDof> parse_dof(std::string_view t) {
  static constexpr AcclaimDof kAll[] = {AcclaimDof::kRx, AcclaimDof::kRy, AcclaimDof::kRz, AcclaimDof::kTx,
                                        AcclaimDof::kTy, AcclaimDof::kTz, AcclaimDof::kL};
  for (AcclaimDof d : kAll) {
    if (iequals(t, acclaim_dof_name(d))) return d;
  }
  return std::nullopt;
}

std::optional<std::array<Axis, 3>> parse_axis_order(std::string_view t) {
  if (t.size() != 3) return std::nullopt;
  std::array<Axis, 3> out{};
  bool seen[3] = {false, false, false};
  for (std::size_t i = 0; i < 3; ++i) {
    const char c = acclaim_detail::lower(t[i]);
    if (c < 'x' || c > 'z') return std::nullopt;
    const int a = c - 'x';
    if (seen[a]) return std::nullopt;
    seen[a] = true;
    out[i] = static_cast<Axis>(a);
  }
  return out;
}

// A bone while its begin/end block is read, with where each field came from.
struct PendingBone {
  AsfBone bone;
  int begin_line = 0;
  bool has_name = false, has_direction = false, has_length = false;
  int limits_line = 0, limits_column = 0;
  int length_line = 0, length_column = 0;
};

class AsfParser {
 public:
  AsfParser(std::string_view text, std::string_view file, Warnings* warnings)
      : reader_(text), file_(file), warnings_(warnings) {}

  Result<AsfSkeleton> run();

 private:
  Error err(const Line& l, const Token& t, std::string msg) const {
    return error_at(file_, l.number, t.column, std::move(msg));
  }
  Error err_eol(const Line& l, std::string msg) const {
    return error_at(file_, l.number, static_cast<int>(l.raw.size()) + 1, std::move(msg));
  }
  void warn(const Line& l, const Token& t, std::string msg) {
    if (warnings_ != nullptr) warnings_->push_back(error_at(file_, l.number, t.column, std::move(msg)));
  }

  // Reads `count` numbers from l.tokens starting at `first`; fails naming the keyword.
  Status numbers(const Line& l, std::size_t first, std::size_t count, std::string_view keyword, double* out) const;
  Status section_line(const Line& l);
  Status units_line(const Line& l);
  Status root_line(const Line& l);
  Status bonedata_line(const Line& l);
  Status bone_field(const Line& l);
  Status finish_bone(const Line& l);
  Status hierarchy_line(const Line& l);
  Result<AsfSkeleton> assemble();

  LineReader reader_;
  std::string_view file_;
  Warnings* warnings_;

  Section section_ = Section::kNone;
  AsfSkeleton out_;
  AsfBone root_;
  bool have_root_ = false;
  bool in_bone_ = false;
  PendingBone pending_;
  std::vector<PendingBone> bones_;                   // file order
  std::unordered_map<std::string, int> bone_index_;  // lower-case name -> index in bones_

  // Hierarchy: parent of each bone (index into bones_, -1 = root, -2 = none yet).
  bool have_hierarchy_ = false;
  bool in_hierarchy_ = false;
  bool hierarchy_done_ = false;
  std::vector<int> parent_;
  std::vector<std::vector<int>> children_;  // [0] = root's children; [i+1] = bones_[i]'s children
  std::vector<std::string> doc_lines_;
};

Status AsfParser::numbers(const Line& l, std::size_t first, std::size_t count, std::string_view keyword,
                          double* out) const {
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t k = first + i;
    if (k >= l.tokens.size()) {
      return err_eol(l, "expected " + std::to_string(count) + (count == 1 ? " number" : " numbers") + " after '" +
                            std::string(keyword) + "', found " + std::to_string(i));
    }
    const auto v = parse_number(l.tokens[k].text);
    if (!v)
      return err(l, l.tokens[k],
                 "expected a number after '" + std::string(keyword) + "', found " + quote_text(l.tokens[k].text));
    out[i] = *v;
  }
  return Ok{};
}

Status AsfParser::section_line(const Line& l) {
  const Token& t = l.tokens[0];
  const std::string kw = to_lower(t.text);
  if (in_bone_)
    return err(l, t,
               "expected 'end' to close the bone begun on line " + std::to_string(pending_.begin_line) + " before " +
                   quote_text(t.text));
  if (in_hierarchy_) return err(l, t, "expected 'end' to close :hierarchy before " + quote_text(t.text));
  if (kw == ":version") {
    section_ = Section::kVersion;
    if (l.tokens.size() > 1) out_.version = std::string(l.tokens[1].text);
  } else if (kw == ":name") {
    section_ = Section::kName;
    if (l.tokens.size() > 1) out_.name = std::string(l.tokens[1].text);
  } else if (kw == ":units") {
    section_ = Section::kUnits;
    if (l.tokens.size() > 1) {
      Line rest = l;
      rest.tokens.erase(rest.tokens.begin());
      return units_line(rest);
    }
  } else if (kw == ":documentation") {
    section_ = Section::kDocumentation;
  } else if (kw == ":root") {
    if (have_root_) return err(l, t, "a second :root section");
    have_root_ = true;
    section_ = Section::kRoot;
  } else if (kw == ":bonedata") {
    if (have_hierarchy_) return err(l, t, "expected :bonedata before :hierarchy (the hierarchy names its bones)");
    section_ = Section::kBoneData;
  } else if (kw == ":hierarchy") {
    if (have_hierarchy_) return err(l, t, "a second :hierarchy section");
    have_hierarchy_ = true;
    section_ = Section::kHierarchy;
  } else {
    warn(l, t, "unknown section " + quote_text(t.text) + " skipped");
    section_ = Section::kUnknown;
  }
  return Ok{};
}

Status AsfParser::units_line(const Line& l) {
  for (std::size_t i = 0; i < l.tokens.size(); i += 2) {
    const Token& key = l.tokens[i];
    if (i + 1 >= l.tokens.size()) return err_eol(l, "expected a value after " + quote_text(key.text));
    const Token& val = l.tokens[i + 1];
    const std::string k = to_lower(key.text);
    if (k == "mass" || k == "length") {
      const auto v = parse_number(val.text);
      if (!v) return err(l, val, "expected a number after '" + k + "', found " + quote_text(val.text));
      if (k == "length" && !(*v > 0.0))
        return err(l, val, "expected a positive length unit, found " + quote_text(val.text));
      (k == "mass" ? out_.units.mass : out_.units.length) = *v;
    } else if (k == "angle") {
      const std::string v = to_lower(val.text);
      if (v == "deg" || v == "degree" || v == "degrees") {
        out_.units.degrees = true;
      } else if (v == "rad" || v == "radian" || v == "radians") {
        out_.units.degrees = false;
      } else {
        return err(l, val, "expected 'deg' or 'rad' after 'angle', found " + quote_text(val.text));
      }
    } else {
      warn(l, key, "unknown unit " + quote_text(key.text) + " skipped");
    }
  }
  return Ok{};
}

Status AsfParser::root_line(const Line& l) {
  const Token& t = l.tokens[0];
  const std::string kw = to_lower(t.text);
  if (kw == "order") {
    root_.dofs.clear();
    for (std::size_t i = 1; i < l.tokens.size(); ++i) {
      const auto d = parse_dof(l.tokens[i].text);
      if (!d || *d == AcclaimDof::kL) {
        return err(l, l.tokens[i],
                   "expected TX, TY, TZ, RX, RY or RZ in the root order, found " + quote_text(l.tokens[i].text));
      }
      if (std::find(root_.dofs.begin(), root_.dofs.end(), *d) != root_.dofs.end()) {
        return err(l, l.tokens[i], "root order lists " + quote_text(l.tokens[i].text) + " twice");
      }
      root_.dofs.push_back(*d);
    }
  } else if (kw == "axis") {
    if (l.tokens.size() < 2) return err_eol(l, "expected a rotation order such as XYZ after 'axis'");
    const auto o = parse_axis_order(l.tokens[1].text);
    if (!o)
      return err(l, l.tokens[1],
                 "expected a rotation order such as XYZ after 'axis', found " + quote_text(l.tokens[1].text));
    root_.axis_order = *o;
  } else if (kw == "position" || kw == "orientation") {
    double v[3];
    if (auto s = numbers(l, 1, 3, kw, v); !s) return s;
    (kw == "position" ? root_.position : root_.axis) = Eigen::Vector3d(v[0], v[1], v[2]);
  } else {
    warn(l, t, "unknown root field " + quote_text(t.text) + " skipped");
  }
  return Ok{};
}

Status AsfParser::bonedata_line(const Line& l) {
  const Token& t = l.tokens[0];
  if (!in_bone_) {
    if (!iequals(t.text, "begin")) return err(l, t, "expected 'begin' to start a bone, found " + quote_text(t.text));
    in_bone_ = true;
    pending_ = PendingBone{};
    pending_.begin_line = l.number;
    return Ok{};
  }
  if (iequals(t.text, "end")) return finish_bone(l);
  if (iequals(t.text, "begin"))
    return err(l, t, "expected 'end' to close the bone begun on line " + std::to_string(pending_.begin_line));
  return bone_field(l);
}

Status AsfParser::bone_field(const Line& l) {
  const Token& t = l.tokens[0];
  const std::string kw = to_lower(t.text);
  AsfBone& b = pending_.bone;
  if (kw == "id") {
    if (l.tokens.size() < 2) return err_eol(l, "expected a number after 'id'");
    const auto v = parse_integer(l.tokens[1].text);
    if (!v || *v > 1000000000)
      return err(l, l.tokens[1], "expected a whole number after 'id', found " + quote_text(l.tokens[1].text));
    b.id = static_cast<int>(*v);
  } else if (kw == "name") {
    if (l.tokens.size() < 2) return err_eol(l, "expected a bone name after 'name'");
    if (l.tokens.size() > 2)
      return err(l, l.tokens[2],
                 "expected one bone name (no spaces), found another word " + quote_text(l.tokens[2].text));
    const Token& n = l.tokens[1];
    const std::string key = to_lower(n.text);
    if (key == "root") return err(l, n, "a bone may not be named " + quote_text(n.text) + " (the root's name)");
    // These would read as keywords in the hierarchy.
    if (key == "begin" || key == "end" || key.front() == ':') {
      return err(l, n, "a bone may not be named " + quote_text(n.text) + " (a keyword of the hierarchy)");
    }
    if (auto it = bone_index_.find(key); it != bone_index_.end()) {
      return err(l, n,
                 "bone name " + quote_text(n.text) + " repeats the bone begun on line " +
                     std::to_string(bones_[static_cast<std::size_t>(it->second)].begin_line) +
                     " (names are case-insensitive)");
    }
    b.name = std::string(n.text);
    pending_.has_name = true;
  } else if (kw == "direction") {
    double v[3];
    if (auto s = numbers(l, 1, 3, kw, v); !s) return s;
    b.direction = Eigen::Vector3d(v[0], v[1], v[2]);
    pending_.has_direction = true;
  } else if (kw == "length") {
    double v[1];
    if (auto s = numbers(l, 1, 1, kw, v); !s) return s;
    if (v[0] < 0.0) return err(l, l.tokens[1], "expected a length >= 0, found " + quote_text(l.tokens[1].text));
    b.length = v[0];
    pending_.has_length = true;
    pending_.length_line = l.number;
    pending_.length_column = l.tokens[1].column;
  } else if (kw == "axis") {
    double v[3];
    if (auto s = numbers(l, 1, 3, kw, v); !s) return s;
    b.axis = Eigen::Vector3d(v[0], v[1], v[2]);
    if (l.tokens.size() > 4) {
      const auto o = parse_axis_order(l.tokens[4].text);
      if (!o)
        return err(
            l, l.tokens[4],
            "expected a rotation order such as XYZ after the axis angles, found " + quote_text(l.tokens[4].text));
      b.axis_order = *o;
    }
  } else if (kw == "dof") {
    b.dofs.clear();
    for (std::size_t i = 1; i < l.tokens.size(); ++i) {
      const auto d = parse_dof(l.tokens[i].text);
      if (!d)
        return err(l, l.tokens[i],
                   "expected rx, ry, rz, tx, ty, tz or l after 'dof', found " + quote_text(l.tokens[i].text));
      if (std::find(b.dofs.begin(), b.dofs.end(), *d) != b.dofs.end()) {
        return err(l, l.tokens[i], "dof " + quote_text(l.tokens[i].text) + " listed twice");
      }
      b.dofs.push_back(*d);
    }
  } else if (kw == "limits") {
    pending_.limits_line = l.number;
    pending_.limits_column = t.column;
    std::vector<double> v;
    auto take = [&](const Line& line, std::size_t first) -> Status {
      for (std::size_t i = first; i < line.tokens.size(); ++i) {
        const auto x = parse_number(line.tokens[i].text, /*allow_non_finite=*/true);
        if (!x || std::isnan(*x))
          return err(line, line.tokens[i],
                     "expected a limit (a number or inf), found " + quote_text(line.tokens[i].text));
        v.push_back(*x);
      }
      return Ok{};
    };
    if (auto s = take(l, 1); !s) return s;
    // Limits continue on following lines that start with a number.
    for (;;) {
      const Line* next = reader_.peek();
      if (next == nullptr || next->tokens.empty() || !parse_number(next->tokens[0].text, true)) break;
      Line cont;
      reader_.next(cont);
      if (auto s = take(cont, 0); !s) return s;
    }
    if (v.size() % 2 != 0)
      return err(l, t, "expected pairs of limits (min max), found " + std::to_string(v.size()) + " numbers");
    b.limits.clear();
    for (std::size_t i = 0; i < v.size(); i += 2) b.limits.push_back(AsfLimit{v[i], v[i + 1]});
  } else if (kw == "bodymass" || kw == "cofmass") {
    // Known Acclaim fields that FK does not use.
  } else {
    warn(l, t, "unknown bone field " + quote_text(t.text) + " skipped");
  }
  return Ok{};
}

Status AsfParser::finish_bone(const Line& l) {
  const Token& t = l.tokens[0];
  const std::string where = " in the bone begun on line " + std::to_string(pending_.begin_line);
  if (!pending_.has_name) return err(l, t, "expected a 'name'" + where);
  if (!pending_.has_direction) return err(l, t, "expected a 'direction' for bone " + quote_text(pending_.bone.name));
  if (!pending_.has_length) return err(l, t, "expected a 'length' for bone " + quote_text(pending_.bone.name));
  AsfBone& b = pending_.bone;
  // Each factor is finite, but their product (the bone's offset) can overflow.
  if (!(b.direction * b.length).allFinite()) {
    return error_at(file_, pending_.length_line, pending_.length_column,
                    "bone " + quote_text(b.name) + ": direction times length is not finite (the offset overflows)");
  }
  if (!b.limits.empty() && b.dofs.empty()) {
    // No dof is ever inferred from limits (fairmotion#59).
    if (warnings_ != nullptr) {
      warnings_->push_back(error_at(file_, pending_.limits_line, pending_.limits_column,
                                    "bone " + quote_text(b.name) + " has limits but no dof: limits ignored"));
    }
    b.limits.clear();
  }
  if (!b.limits.empty() && b.limits.size() != b.dofs.size()) {
    return error_at(file_, pending_.limits_line, pending_.limits_column,
                    "expected " + std::to_string(b.dofs.size()) + " limit pairs (one per dof) for bone " +
                        quote_text(b.name) + ", found " + std::to_string(b.limits.size()));
  }
  bone_index_.emplace(to_lower(b.name), static_cast<int>(bones_.size()));
  bones_.push_back(std::move(pending_));
  in_bone_ = false;
  return Ok{};
}

Status AsfParser::hierarchy_line(const Line& l) {
  const Token& t = l.tokens[0];
  if (hierarchy_done_)
    return err(l, t, "expected a section (':name') after the hierarchy's 'end', found " + quote_text(t.text));
  if (!in_hierarchy_) {
    if (!iequals(t.text, "begin"))
      return err(l, t, "expected 'begin' to start the hierarchy, found " + quote_text(t.text));
    in_hierarchy_ = true;
    parent_.assign(bones_.size(), -2);
    children_.assign(bones_.size() + 1, {});
    return Ok{};
  }
  if (iequals(t.text, "end")) {
    in_hierarchy_ = false;
    hierarchy_done_ = true;
    return Ok{};
  }
  int parent = -1;
  if (!iequals(t.text, "root")) {
    const auto it = bone_index_.find(to_lower(t.text));
    if (it == bone_index_.end()) return err(l, t, "unknown bone " + quote_text(t.text) + " in the hierarchy");
    parent = it->second;
  }
  if (l.tokens.size() < 2) return err_eol(l, "expected the children of " + quote_text(t.text));
  for (std::size_t i = 1; i < l.tokens.size(); ++i) {
    const Token& c = l.tokens[i];
    if (iequals(c.text, "root")) return err(l, c, "the root cannot be a child");
    const auto it = bone_index_.find(to_lower(c.text));
    if (it == bone_index_.end()) return err(l, c, "unknown bone " + quote_text(c.text) + " in the hierarchy");
    const int child = it->second;
    if (child == parent) return err(l, c, "bone " + quote_text(c.text) + " cannot be its own child");
    if (parent_[static_cast<std::size_t>(child)] != -2)
      return err(l, c, "bone " + quote_text(c.text) + " already has a parent");
    parent_[static_cast<std::size_t>(child)] = parent;
    children_[static_cast<std::size_t>(parent + 1)].push_back(child);
  }
  return Ok{};
}

Result<AsfSkeleton> AsfParser::assemble() {
  const int last = reader_.last_line();
  const int end_col = 1;
  if (in_bone_)
    return error_at(
        file_, last, end_col,
        "file ends inside the bone begun on line " + std::to_string(pending_.begin_line) + "; expected 'end'");
  if (in_hierarchy_) return error_at(file_, last, end_col, "file ends inside :hierarchy; expected 'end'");
  if (!have_root_) return error_at(file_, last, end_col, "expected a :root section");
  if (!bones_.empty() && !have_hierarchy_) return error_at(file_, last, end_col, "expected a :hierarchy section");
  if (have_hierarchy_ && !hierarchy_done_)
    return error_at(file_, last, end_col, "expected 'begin' ... 'end' in :hierarchy");

  root_.name = "root";
  root_.id = 0;
  root_.parent = -1;
  out_.bones.push_back(std::move(root_));
  out_.bones.reserve(bones_.size() + 1);
  // Pre-order depth-first walk with an explicit stack (a long chain cannot
  // overflow the call stack). Stack items: (bones_ index, parent in out_.bones).
  std::vector<std::pair<int, int>> stack;
  std::vector<char> reached(bones_.size(), 0);
  auto push_children = [&](int src, int dst) {
    if (children_.empty()) return;  // no bones, no hierarchy
    const auto& kids = children_[static_cast<std::size_t>(src + 1)];
    for (auto it = kids.rbegin(); it != kids.rend(); ++it) stack.emplace_back(*it, dst);
  };
  push_children(-1, 0);
  while (!stack.empty()) {
    const auto [src, parent] = stack.back();
    stack.pop_back();
    reached[static_cast<std::size_t>(src)] = 1;
    AsfBone b = bones_[static_cast<std::size_t>(src)].bone;
    b.parent = parent;
    out_.bones.push_back(std::move(b));
    push_children(src, static_cast<int>(out_.bones.size()) - 1);
  }
  if (out_.bones.size() != bones_.size() + 1) {
    for (std::size_t i = 0; i < bones_.size(); ++i) {
      if (reached[i] == 0) {
        return error_at(file_, bones_[i].begin_line, 1,
                        "bone " + quote_text(bones_[i].bone.name) + " is not connected to the root by :hierarchy");
      }
    }
  }
  out_.documentation.clear();
  for (std::size_t i = 0; i < doc_lines_.size(); ++i) {
    if (i > 0) out_.documentation += '\n';
    out_.documentation += doc_lines_[i];
  }
  return std::move(out_);
}

Result<AsfSkeleton> AsfParser::run() {
  Line l;
  while (reader_.next(l)) {
    if (l.tokens.empty()) continue;
    if (l.tokens[0].text.front() == ':') {
      if (auto s = section_line(l); !s) return s.error();
      continue;
    }
    Status s = Ok{};
    switch (section_) {
      case Section::kNone:
        return err(l, l.tokens[0], "expected a section keyword such as ':root', found " + quote_text(l.tokens[0].text));
      case Section::kDocumentation: {
        std::string_view r = l.raw;
        while (!r.empty() && (r.front() == ' ' || r.front() == '\t')) r.remove_prefix(1);
        while (!r.empty() && (r.back() == ' ' || r.back() == '\t')) r.remove_suffix(1);
        doc_lines_.emplace_back(r);
        break;
      }
      case Section::kUnits:
        s = units_line(l);
        break;
      case Section::kRoot:
        s = root_line(l);
        break;
      case Section::kBoneData:
        s = bonedata_line(l);
        break;
      case Section::kHierarchy:
        s = hierarchy_line(l);
        break;
      case Section::kVersion:
      case Section::kName:
        return err(l, l.tokens[0],
                   "expected a section keyword such as ':units', found " + quote_text(l.tokens[0].text));
      case Section::kUnknown:
        break;
    }
    if (!s) return s.error();
  }
  return assemble();
}

}  // namespace

Result<AsfSkeleton> parse_asf(std::string_view text, std::string_view file_label, Warnings* out_warnings) {
  return AsfParser(text, file_label, out_warnings).run();
}

Result<AsfSkeleton> read_asf(const std::filesystem::path& path, Warnings* out_warnings) {
  auto text = read_file(path);
  if (!text) return text.error();
  return parse_asf(*text, path.string(), out_warnings);
}

// ---- writer ------------------------------------------------------------

std::string format_asf(const AsfSkeleton& s) {
  std::string out;
  out.reserve(256 + 256 * s.bones.size());
  out += "# ASF written by gmr\n";
  if (!s.version.empty()) out += ":version " + s.version + "\n";
  if (!s.name.empty()) out += ":name " + s.name + "\n";
  out += ":units\n  mass ";
  put(out, s.units.mass);
  out += "\n  length ";
  put(out, s.units.length);
  out += s.units.degrees ? "\n  angle deg\n" : "\n  angle rad\n";
  if (!s.documentation.empty()) {
    out += ":documentation\n";
    std::size_t b = 0;
    while (b <= s.documentation.size()) {
      std::size_t e = s.documentation.find('\n', b);
      if (e == std::string::npos) e = s.documentation.size();
      std::string_view line(s.documentation.data() + b, e - b);
      // A documentation line that starts with ':' would read back as a section.
      out += (!line.empty() && line.front() == ':') ? "   \\" : "   ";
      out += line;
      out += '\n';
      b = e + 1;
    }
  }
  if (!s.bones.empty()) {
    const AsfBone& r = s.bones[0];
    out += ":root\n   order";
    for (AcclaimDof d : r.dofs) {
      out += ' ';
      for (char c : acclaim_dof_name(d)) out += static_cast<char>(c - 'a' + 'A');
    }
    out += "\n   axis ";
    put_order(out, r.axis_order);
    out += "\n   position ";
    put3(out, r.position);
    out += "\n   orientation ";
    put3(out, r.axis);
    out += '\n';
  }
  out += ":bonedata\n";
  for (std::size_t i = 1; i < s.bones.size(); ++i) {
    const AsfBone& b = s.bones[i];
    out += "  begin\n     id " + std::to_string(b.id) + "\n     name " + b.name + "\n     direction ";
    put3(out, b.direction);
    out += "\n     length ";
    put(out, b.length);
    out += "\n     axis ";
    put3(out, b.axis);
    out += ' ';
    put_order(out, b.axis_order);
    out += '\n';
    if (!b.dofs.empty()) {
      out += "     dof";
      for (AcclaimDof d : b.dofs) {
        out += ' ';
        out += acclaim_dof_name(d);
      }
      out += '\n';
      for (std::size_t k = 0; k < b.limits.size(); ++k) {
        out += k == 0 ? "     limits (" : "            (";
        put(out, b.limits[k].min);
        out += ' ';
        put(out, b.limits[k].max);
        out += ")\n";
      }
    }
    out += "  end\n";
  }
  out += ":hierarchy\n  begin\n";
  std::vector<std::vector<int>> children(s.bones.size());
  for (std::size_t i = 1; i < s.bones.size(); ++i) {
    const int p = s.bones[i].parent;
    if (p >= 0 && static_cast<std::size_t>(p) < s.bones.size())
      children[static_cast<std::size_t>(p)].push_back(static_cast<int>(i));
  }
  for (std::size_t p = 0; p < s.bones.size(); ++p) {
    if (children[p].empty()) continue;
    out += "    " + s.bones[p].name;
    for (int c : children[p]) out += ' ' + s.bones[static_cast<std::size_t>(c)].name;
    out += '\n';
  }
  out += "  end\n";
  return out;
}

Status write_asf(const AsfSkeleton& skeleton, const std::filesystem::path& path) {
  return write_file_atomic(path, format_asf(skeleton));
}

}  // namespace gmr
