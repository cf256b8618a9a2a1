// TRC (OpenSim marker text) reader and writer.
//
//   PathFileType  4  (X/Y/Z)  name
//   DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  ...   (keys)
//   250       250         126        44          mm     250           ...   (values)
//   Frame#  Time  M1        M2  ...
//                 X1 Y1 Z1  X2 Y2 Z2 ...                                     (optional)
//   (blank lines)
//   1  0.000  x y z  x y z ...
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>

#include "gmr/core/file_util.h"
#include "gmr/core/limits.h"
#include "gmr/markers/trc.h"
#include "names.h"

namespace gmr {
namespace {

enum class Separator { kTab, kComma, kSpaces };

struct Cell {
  std::string_view text;  // trimmed of spaces (and of tabs in the comma and space modes)
  int column = 0;         // 1-based column of the cell's first byte
};

struct Line {
  std::string_view text;  // without the line end
  int number = 0;         // 1-based
  bool ended = false;     // followed by a line end (false only for a last line without one)
};

std::vector<Line> split_lines(std::string_view text) {
  std::vector<Line> out;
  std::size_t pos = 0;
  int number = 1;
  while (pos < text.size()) {
    std::size_t e = pos;
    while (e < text.size() && text[e] != '\n' && text[e] != '\r') ++e;
    Line l{text.substr(pos, e - pos), number++, e < text.size()};
    out.push_back(l);
    if (e < text.size() && text[e] == '\r' && e + 1 < text.size() && text[e + 1] == '\n') ++e;
    pos = e + 1;
  }
  return out;
}

bool is_blank(char c) { return c == ' ' || c == '\t'; }

std::vector<Cell> split_cells(std::string_view line, Separator sep) {
  std::vector<Cell> out;
  const auto push = [&](std::size_t b, std::size_t e) {
    while (b < e && is_blank(line[b])) ++b;
    while (e > b && is_blank(line[e - 1])) --e;
    out.push_back({line.substr(b, e - b), static_cast<int>(b) + 1});
  };
  if (sep == Separator::kSpaces) {
    std::size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && is_blank(line[i])) ++i;
      if (i == line.size()) break;
      const std::size_t b = i;
      while (i < line.size() && !is_blank(line[i])) ++i;
      push(b, i);
    }
    return out;
  }
  const char c = sep == Separator::kTab ? '\t' : ',';
  std::size_t b = 0;
  for (std::size_t i = 0; i <= line.size(); ++i) {
    if (i == line.size() || line[i] == c) {
      push(b, i);
      b = i + 1;
    }
  }
  return out;
}

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  }
  return true;
}

// A finite number (optional '+', E-notation): true and `out` set; "nan" in
// any case gives NaN when allow_nan.
bool parse_number(std::string_view s, double& out, bool allow_nan) {
  if (allow_nan && iequals(s, "nan")) {
    out = std::numeric_limits<double>::quiet_NaN();
    return true;
  }
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  if (s.empty() || s[0] == '+' || s[0] == 'n' || s[0] == 'N' || s[0] == 'i' || s[0] == 'I') return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && std::isfinite(out);
}

bool parse_integer(std::string_view s, std::int64_t& out) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  const auto r = std::from_chars(s.data(), s.data() + s.size(), out);
  if (r.ec == std::errc() && r.ptr == s.data() + s.size()) return true;
  // "185.0" and the like.
  double d = 0;
  if (!parse_number(s, d, false) || d != std::floor(d) || std::fabs(d) > 9e15) return false;
  out = static_cast<std::int64_t>(d);
  return true;
}

Error at(std::string_view file, int line, int column, std::string message) {
  return Error{std::string(file), line, column, std::move(message)};
}

std::string quote_cell(std::string_view s) {
  constexpr std::size_t kMax = 40;
  std::string out(1, '\'');
  out.append(s.substr(0, kMax));
  if (s.size() > kMax) out.append("...");
  out.push_back('\'');
  return out;
}

}  // namespace

Result<MarkerTrajectories> parse_trc(std::string_view text, std::string_view label, Warnings* out_warnings) {
  const auto warn = [&](int line, int column, std::string message) {
    if (out_warnings) out_warnings->push_back(at(label, line, column, std::move(message)));
  };
  const std::vector<Line> lines = split_lines(text);
  const int last_line = lines.empty() ? 1 : lines.back().number;
  const auto missing = [&](std::size_t i, const char* what) {
    return at(label, i < lines.size() ? lines[i].number : last_line + 1, 1,
              std::string("expected ") + what + (i < lines.size() ? "" : ", found the end of the file"));
  };
  if (lines.empty()) return at(label, 1, 1, "empty file: expected a TRC header (PathFileType ...)");
  const Separator sep = lines[0].text.find('\t') != std::string_view::npos  ? Separator::kTab
                        : lines[0].text.find(',') != std::string_view::npos ? Separator::kComma
                                                                            : Separator::kSpaces;
  const std::vector<Cell> first = split_cells(lines[0].text, sep);
  if (first.empty() || !iequals(first[0].text, "PathFileType")) {
    return at(label, 1, 1, "expected 'PathFileType' at the start of a TRC file");
  }
  if (lines.size() < 4)
    return missing(lines.size(), lines.size() == 1   ? "the header keys line"
                                 : lines.size() == 2 ? "the header values line"
                                                     : "the marker names line (Frame# Time ...)");

  MarkerTrajectories out;
  // Header keys and values, matched by position, keys case-insensitive.
  const std::vector<Cell> keys = split_cells(lines[1].text, sep);
  const std::vector<Cell> values = split_cells(lines[2].text, sep);
  std::int64_t declared_frames = -1, declared_markers = -1;
  int frames_col = 1, markers_col = 1;
  bool have_rate = false;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    if (keys[k].text.empty()) continue;
    const Cell v = k < values.size() ? values[k] : Cell{{}, static_cast<int>(lines[2].text.size()) + 1};
    const std::string_view key = keys[k].text;
    if (iequals(key, "DataRate") || (iequals(key, "CameraRate") && !have_rate)) {
      double r = 0;
      if (!parse_number(v.text, r, false) || r < 0) {
        return at(label, lines[2].number, v.column,
                  std::string(key) + " must be a number >= 0, found " + quote_cell(v.text));
      }
      out.frame_rate = r;
      have_rate = have_rate || iequals(key, "DataRate");
    } else if (iequals(key, "NumFrames") || iequals(key, "NumMarkers")) {
      std::int64_t n = 0;
      if (!parse_integer(v.text, n) || n < 0) {
        return at(label, lines[2].number, v.column,
                  std::string(key) + " must be a whole number >= 0, found " + quote_cell(v.text));
      }
      (iequals(key, "NumFrames") ? declared_frames : declared_markers) = n;
      (iequals(key, "NumFrames") ? frames_col : markers_col) = v.column;
    } else if (iequals(key, "Units")) {
      out.units = std::string(v.text);
    }
  }

  // Marker names: the non-empty cells after Frame# and Time.
  const std::vector<Cell> names = split_cells(lines[3].text, sep);
  if (names.size() < 2 || !iequals(names[0].text, "Frame#") || !iequals(names[1].text, "Time")) {
    return at(label, lines[3].number, names.empty() ? 1 : names[0].column,
              "expected 'Frame#' and 'Time' to start the marker names line");
  }
  for (std::size_t i = 2; i < names.size(); ++i) {
    if (!names[i].text.empty()) out.names.emplace_back(names[i].text);
  }
  if (detail::make_names_unique(out.names)) {
    warn(lines[3].number, 1, "repeated marker names: later ones renamed with _2, _3, ...");
  }
  const std::size_t markers = out.names.size();
  if (declared_markers >= 0 && static_cast<std::size_t>(declared_markers) != markers) {
    warn(lines[2].number, markers_col,
         "NumMarkers is " + std::to_string(declared_markers) + " but " + std::to_string(markers) +
             " marker names follow: using the names");
  }

  // Optional coordinate labels (X1 Y1 Z1 ..., from any number), then rows.
  std::size_t i = 4;
  if (i < lines.size()) {
    const auto cells = split_cells(lines[i].text, sep);
    for (const Cell& c : cells) {
      if (c.text.empty()) continue;
      if (c.text[0] == 'X' || c.text[0] == 'x') ++i;
      break;
    }
  }
  const std::size_t columns = 2 + 3 * markers;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::int64_t expected_frame = 0;
  bool gap_warned = false, time_warned = false;
  std::vector<Cell> cells;
  for (; i < lines.size(); ++i) {
    const Line& line = lines[i];
    cells = split_cells(line.text, sep);
    std::size_t used = cells.size();
    while (used > 0 && cells[used - 1].text.empty()) --used;
    if (used == 0) continue;  // blank line, or a line of empty cells
    if (used > columns) {
      return at(label, line.number, cells[columns].column,
                "row has " + std::to_string(used) + " values, expected " + std::to_string(columns) +
                    " (Frame#, Time and 3 per marker for " + std::to_string(markers) + " markers)");
    }
    if (cells.size() < columns) {
      const int end_col = static_cast<int>(line.text.size()) + 1;
      return at(label, line.number, end_col,
                std::string(line.ended ? "row ends" : "file ends") + " after " + std::to_string(cells.size()) + " of " +
                    std::to_string(columns) + " values (Frame#, Time and 3 per marker)" +
                    (line.ended ? "" : ": truncated"));
    }
    if (auto s = check_frame_count(out.frame_count + 1, 3 * markers); !s.ok()) {
      return at(label, line.number, cells[0].column, "one frame too many: " + s.error().message);
    }
    std::int64_t frame = 0;
    if (!parse_integer(cells[0].text, frame)) {
      return at(label, line.number, cells[0].column, "expected a frame number, found " + quote_cell(cells[0].text));
    }
    double time = 0;
    if (!parse_number(cells[1].text, time, false)) {
      return at(label, line.number, cells[1].column, "expected a time in seconds, found " + quote_cell(cells[1].text));
    }
    if (out.frame_count == 0) {
      out.first_frame = frame;
      out.start_time = time;
      expected_frame = frame;
    }
    if (frame != expected_frame && !gap_warned) {
      warn(line.number, cells[0].column,
           "frame number " + std::to_string(frame) + " where " + std::to_string(expected_frame) +
               " was expected: rows kept in file order");
      gap_warned = true;
    }
    expected_frame = frame + 1;
    if (out.frame_rate > 0 && !time_warned) {
      const double want = out.start_time + static_cast<double>(out.frame_count) / out.frame_rate;
      if (std::fabs(time - want) > 0.1 / out.frame_rate) {
        warn(line.number, cells[1].column,
             "Time " + std::string(cells[1].text) + " does not match DataRate " + format_double(out.frame_rate) +
                 " (expected " + format_double(want) + ")");
        time_warned = true;
      }
    }
    const std::size_t base = out.positions.size();
    out.positions.resize(base + 3 * markers);
    for (std::size_t m = 0; m < markers; ++m) {
      bool missing_point = false;
      for (int a = 0; a < 3; ++a) {
        const Cell& c = cells[2 + 3 * m + static_cast<std::size_t>(a)];
        double v = nan;
        if (!c.text.empty() && !parse_number(c.text, v, true)) {
          return at(label, line.number, c.column,
                    "expected a number, NaN or an empty cell for " + out.names[m] + ", found " + quote_cell(c.text));
        }
        missing_point = missing_point || std::isnan(v);
        out.positions[base + 3 * m + static_cast<std::size_t>(a)] = v;
      }
      // A point with any coordinate missing is missing as a whole.
      if (missing_point) {
        for (int a = 0; a < 3; ++a) out.positions[base + 3 * m + static_cast<std::size_t>(a)] = nan;
      }
    }
    ++out.frame_count;
  }
  if (declared_frames >= 0 && static_cast<std::size_t>(declared_frames) != out.frame_count) {
    warn(lines[2].number, frames_col,
         "NumFrames is " + std::to_string(declared_frames) + " but the file holds " + std::to_string(out.frame_count) +
             " rows: loaded the rows");
  }
  return out;
}

Result<MarkerTrajectories> read_trc(const std::filesystem::path& path, Warnings* out_warnings) {
  auto text = read_file(path);
  if (!text) return text.error();
  return parse_trc(*text, path.string(), out_warnings);
}

Result<std::string> format_trc(const MarkerTrajectories& data, std::string_view file_name) {
  if (auto s = data.validate(); !s) return s.error();
  for (const std::string& n : data.names) {
    if (n.find_first_of("\t\r\n") != std::string::npos || is_blank(n.front()) || is_blank(n.back())) {
      return make_error("marker name " + quote_cell(n) + " cannot be written to TRC (tab, line break or edge space)");
    }
  }
  if (data.units.find_first_of("\t\r\n") != std::string::npos)
    return make_error("units cannot hold tabs or line breaks");
  std::string name(file_name.empty() ? std::string_view("markers.trc") : file_name);
  for (char& c : name) {
    if (c == '\t' || c == '\r' || c == '\n') c = '_';
  }
  const std::size_t m = data.marker_count();
  const std::string rate = format_double(data.frame_rate);
  const std::string frames = std::to_string(data.frame_count);
  std::string out;
  out.reserve(256 + data.frame_count * (32 + m * 3 * 12));
  out += "PathFileType\t4\t(X/Y/Z)\t" + name + "\n";
  out += "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n";
  out += rate + "\t" + rate + "\t" + frames + "\t" + std::to_string(m) + "\t" + data.units + "\t" + rate + "\t" +
         std::to_string(data.first_frame) + "\t" + frames + "\n";
  out += "Frame#\tTime";
  for (const std::string& n : data.names) out += "\t" + n + "\t\t";
  out += "\n\t";
  for (std::size_t k = 1; k <= m; ++k) {
    const std::string s = std::to_string(k);
    out += "\tX" + s + "\tY" + s + "\tZ" + s;
  }
  out += "\n\n";
  for (std::size_t f = 0; f < data.frame_count; ++f) {
    const double t =
        data.start_time + (data.frame_rate > 0 ? static_cast<double>(f) / data.frame_rate : static_cast<double>(f));
    out += std::to_string(data.first_frame + static_cast<std::int64_t>(f));
    out += '\t';
    out += format_double(t);
    for (std::size_t k = 0; k < 3 * m; ++k) {
      const double v = data.positions[f * 3 * m + k];
      out += '\t';
      if (std::isnan(v)) {
        out += "NaN";
      } else {
        out += format_double(v);
      }
    }
    out += '\n';
  }
  return out;
}

Status write_trc(const MarkerTrajectories& data, const std::filesystem::path& path) {
  auto text = format_trc(data, path.filename().string());
  if (!text) {
    Error e = text.error();
    e.file = path.string();
    return e;
  }
  return write_file_atomic(path, *text);
}

}  // namespace gmr
