// AMC reader: header keywords, then frames: a line holding only a frame number,
// followed by one line per bone: its name and its dof values.
#include <algorithm>
#include <unordered_map>

#include "acclaim_text.h"
#include "gmr/acclaim/amc.h"
#include "gmr/core/file_util.h"
#include "gmr/core/limits.h"

namespace gmr {

using acclaim_detail::error_at;
using acclaim_detail::Line;
using acclaim_detail::LineReader;
using acclaim_detail::lower;
using acclaim_detail::parse_integer;
using acclaim_detail::parse_number;
using acclaim_detail::put;
using acclaim_detail::put3;
using acclaim_detail::put_order;
using acclaim_detail::quote_text;
using acclaim_detail::to_lower;

namespace {

// "dof rx ry rz", or for the root "order TX TY TZ RX RY RZ", as the ASF spells them.
std::string dof_list(const AsfBone& b) {
  const bool root = b.parent < 0;
  std::string s = root ? "order" : "dof";
  for (AcclaimDof d : b.dofs) {
    s += ' ';
    for (char c : acclaim_dof_name(d)) s += root ? static_cast<char>(c - 'a' + 'A') : c;
  }
  return b.dofs.empty() ? s + " none" : s;
}

}  // namespace

Result<AmcMotion> parse_amc(std::string_view text, std::string_view file, const AsfSkeleton& skeleton,
                            Warnings* out_warnings) {
  AmcMotion out;
  out.degrees = skeleton.units.degrees;
  const std::size_t stride = static_cast<std::size_t>(skeleton.value_count());
  std::unordered_map<std::string, int> index;
  std::vector<std::size_t> offset(skeleton.bones.size());
  std::size_t next_offset = 0;  // value_offset(b), summed as we go (it is linear in b)
  for (std::size_t b = 0; b < skeleton.bones.size(); ++b) {
    index.emplace(to_lower(skeleton.bones[b].name), static_cast<int>(b));
    offset[b] = next_offset;
    next_offset += skeleton.bones[b].dofs.size();
  }
  // Each frame costs stride values even when the file lists few bones; bound
  // the total by the text size so a file of bare frame numbers cannot make us
  // allocate without limit (a fully specified frame needs >= 2 bytes a value).
  const std::size_t max_values = 16 * text.size() + stride;

  std::vector<char> seen(skeleton.bones.size(), 0);
  std::size_t missing_total = 0;
  int first_missing_frame_line = 0;
  bool gap_warned = false;
  bool in_frames = false;
  int frame_line = 0;
  std::size_t listed = 0;  // bone lines in the current frame

  auto close_frame = [&]() -> Status {
    if (!in_frames) return Ok{};
    if (stride > 0 && listed == 0) {
      return error_at(file, frame_line, 1,
                      "expected bone data after frame number " + std::to_string(out.frame_numbers.back()));
    }
    for (std::size_t b = 0; b < skeleton.bones.size(); ++b) {
      if (!skeleton.bones[b].dofs.empty() && seen[b] == 0) {
        if (missing_total == 0) first_missing_frame_line = frame_line;
        ++missing_total;
      }
    }
    return Ok{};
  };

  LineReader reader(text);
  Line l;
  std::string key;
  while (reader.next(l)) {
    if (l.tokens.empty()) continue;
    const auto& t0 = l.tokens[0];
    if (t0.text.front() == ':') {
      if (in_frames)
        return error_at(file, l.number, t0.column,
                        "expected a frame number or a bone name, found " + quote_text(t0.text));
      const std::string kw = to_lower(t0.text);
      if (kw == ":fully-specified") {
        out.fully_specified = true;
      } else if (kw == ":degrees") {
        out.degrees = true;
      } else if (kw == ":radians") {
        out.degrees = false;
      } else if (out_warnings != nullptr) {
        out_warnings->push_back(
            error_at(file, l.number, t0.column, "unknown keyword " + quote_text(t0.text) + " skipped"));
      }
      continue;
    }
    if (l.tokens.size() == 1) {
      if (const auto n = parse_integer(t0.text)) {
        if (auto s = close_frame(); !s) return s.error();
        if (!out.frame_numbers.empty()) {
          const long long prev = out.frame_numbers.back();
          if (*n <= prev) {
            return error_at(file, l.number, t0.column,
                            "expected a frame number above " + std::to_string(prev) + ", found " + std::to_string(*n));
          }
          if (*n != prev + 1 && !gap_warned && out_warnings != nullptr) {
            gap_warned = true;
            out_warnings->push_back(error_at(file, l.number, t0.column,
                                             "frame numbers jump from " + std::to_string(prev) + " to " +
                                                 std::to_string(*n) +
                                                 "; frames are kept in file order, not resampled"));
          }
        }
        if (out.values.size() + stride > max_values) {
          return error_at(file, l.number, t0.column,
                          "too many frames for the size of the file (frames list almost no bones)");
        }
        if (auto s = check_frame_count(out.frame_count + 1, stride); !s.ok()) {
          return error_at(file, l.number, t0.column, "one frame too many: " + s.error().message);
        }
        out.frame_numbers.push_back(*n);
        out.values.resize(out.values.size() + stride, 0.0);
        ++out.frame_count;
        std::fill(seen.begin(), seen.end(), 0);
        in_frames = true;
        frame_line = l.number;
        listed = 0;
        continue;
      }
    }
    if (!in_frames) {
      return error_at(file, l.number, t0.column,
                      "expected a frame number before bone data, found " + quote_text(t0.text));
    }
    key.assign(t0.text);
    for (char& c : key) c = lower(c);
    const auto it = index.find(key);
    if (it == index.end()) {
      return error_at(file, l.number, t0.column, "bone " + quote_text(t0.text) + " is not in the skeleton");
    }
    const std::size_t b = static_cast<std::size_t>(it->second);
    const AsfBone& bone = skeleton.bones[b];
    if (seen[b] != 0) {
      return error_at(
          file, l.number, t0.column,
          "bone " + quote_text(t0.text) + " listed twice in frame " + std::to_string(out.frame_numbers.back()));
    }
    seen[b] = 1;
    ++listed;
    const std::size_t n = l.tokens.size() - 1;
    if (n != bone.dofs.size()) {
      const int col = n > bone.dofs.size() ? l.tokens[bone.dofs.size() + 1].column : static_cast<int>(l.raw.size()) + 1;
      return error_at(file, l.number, col,
                      "expected " + std::to_string(bone.dofs.size()) + " values for bone " + quote_text(bone.name) +
                          " (" + dof_list(bone) + "), found " + std::to_string(n));
    }
    double* dst = out.values.data() + (out.frame_count - 1) * stride + offset[b];
    for (std::size_t i = 0; i < n; ++i) {
      const auto& tok = l.tokens[i + 1];
      const auto v = parse_number(tok.text);
      if (!v) return error_at(file, l.number, tok.column, "expected a finite number, found " + quote_text(tok.text));
      dst[i] = *v;
    }
  }
  if (auto s = close_frame(); !s) return s.error();
  if (out.frame_count == 0)
    return error_at(file, reader.last_line(), 1, "expected at least one frame (a frame number, then bone lines)");
  if (missing_total > 0 && out_warnings != nullptr) {
    out_warnings->push_back(
        error_at(file, first_missing_frame_line, 1,
                 std::to_string(missing_total) +
                     " bone entries missing from frames (first in the frame here); they keep the value 0"));
  }
  return out;
}

Result<AmcMotion> read_amc(const std::filesystem::path& path, const AsfSkeleton& skeleton, Warnings* out_warnings) {
  auto text = read_file(path);
  if (!text) return text.error();
  return parse_amc(*text, path.string(), skeleton, out_warnings);
}

// ---- writer ------------------------------------------------------------

Result<std::string> format_amc(const AsfSkeleton& s, const AmcMotion& m) {
  const std::size_t stride = static_cast<std::size_t>(s.value_count());
  if (m.values.size() != m.frame_count * stride) {
    return make_error("AMC motion has " + std::to_string(m.values.size()) + " values, expected " +
                      std::to_string(m.frame_count) + " frames x " + std::to_string(stride));
  }
  bool numbered = m.frame_numbers.size() == m.frame_count;
  for (std::size_t f = 1; numbered && f < m.frame_numbers.size(); ++f) {
    numbered = m.frame_numbers[f] > m.frame_numbers[f - 1];
  }
  if (numbered && !m.frame_numbers.empty()) numbered = m.frame_numbers.front() >= 0;
  std::string out;
  out.reserve(64 + m.values.size() * 10 + m.frame_count * s.bones.size() * 10);
  out += "# AMC written by gmr\n:FULLY-SPECIFIED\n";
  out += m.degrees ? ":DEGREES\n" : ":RADIANS\n";
  std::size_t k = 0;
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    out += std::to_string(numbered ? m.frame_numbers[f] : static_cast<long long>(f) + 1);
    out += '\n';
    for (const AsfBone& b : s.bones) {
      if (b.dofs.empty()) continue;
      out += b.name;
      for (std::size_t d = 0; d < b.dofs.size(); ++d) {
        out += ' ';
        put(out, m.values[k++]);
      }
      out += '\n';
    }
  }
  return out;
}

Status write_amc(const AsfSkeleton& skeleton, const AmcMotion& motion, const std::filesystem::path& path) {
  auto text = format_amc(skeleton, motion);
  if (!text) return text.error();
  return write_file_atomic(path, *text);
}

}  // namespace gmr
