#include "gmr/io/positions_csv.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <string>

#include "core/number_format.h"
#include "gmr/core/file_util.h"

namespace gmr {

std::string csv_field(std::string_view s) {
  if (s.find_first_of(",\"\r\n") == std::string_view::npos) return std::string(s);
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  out += '"';
  return out;
}

namespace {

void append_number(std::string& out, double v) {
  if (v == 0.0) v = 0.0;  // "-0" and "0" are the same position: print one form
  char buf[32];
  out.append(buf, detail::format_shortest(buf, v));
}

// ",qw,qx,qy,qz" (qw >= 0: one of the two quaternions) or ",r00,...,r22".
void append_orientation(std::string& buf, const Eigen::Matrix3d& w, OrientationColumns columns) {
  if (columns == OrientationColumns::kQuaternion) {
    Eigen::Quaterniond q(w);
    q.normalize();
    if (q.w() < 0) q.coeffs() = -q.coeffs();
    for (double v : {q.w(), q.x(), q.y(), q.z()}) {
      buf += ',';
      append_number(buf, v);
    }
    return;
  }
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      buf += ',';
      append_number(buf, w(r, c));
    }
  }
}

}  // namespace

void write_pose_header(std::ostream& out, const PoseColumns& columns) {
  out << "frame,joint,x,y,z";
  if (columns.orientations == OrientationColumns::kQuaternion) out << ",qw,qx,qy,qz";
  if (columns.orientations == OrientationColumns::kMatrix) out << ",r00,r01,r02,r10,r11,r12,r20,r21,r22";
  if (columns.local_transforms) out << ",lqw,lqx,lqy,lqz,ltx,lty,ltz";
  out << '\n';
}

void write_pose_rows(std::ostream& out, const Skeleton& skeleton, const PoseRows& rows, std::size_t first_frame,
                     const PoseColumns& columns) {
  const std::size_t joints = skeleton.size();
  if (joints == 0) return;
  std::vector<std::string> names;
  names.reserve(joints);
  for (const Joint& j : skeleton.joints()) names.push_back(csv_field(j.name));
  std::string buf;
  buf.reserve(1 << 16);
  const std::size_t frames = rows.positions.size() / joints;
  for (std::size_t f = 0; f < frames; ++f) {
    const std::string frame = std::to_string(first_frame + f);
    for (std::size_t j = 0; j < joints; ++j) {
      const std::size_t k = f * joints + j;
      buf += frame;
      buf += ',';
      buf += names[j];
      for (int i = 0; i < 3; ++i) {
        buf += ',';
        append_number(buf, rows.positions[k][i]);
      }
      if (columns.orientations) append_orientation(buf, rows.orientations[k], *columns.orientations);
      if (columns.local_transforms) {
        Eigen::Quaterniond q = rows.local_rotations[k].normalized();
        if (q.w() < 0) q.coeffs() = -q.coeffs();
        for (double v : {q.w(), q.x(), q.y(), q.z()}) {
          buf += ',';
          append_number(buf, v);
        }
        for (int i = 0; i < 3; ++i) {
          buf += ',';
          append_number(buf, rows.local_translations[k][i]);
        }
      }
      buf += '\n';
    }
    if (buf.size() > (1 << 16) - 1024) {
      out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
      buf.clear();
    }
  }
  out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
}

void write_positions_csv_header(std::ostream& out) { write_pose_header(out, {}); }

void write_positions_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                              std::size_t first_frame) {
  write_pose_rows(out, skeleton,
                  PoseRows{.positions = positions, .orientations = {}, .local_rotations = {}, .local_translations = {}},
                  first_frame, {});
}

void write_poses_csv_header(std::ostream& out, OrientationColumns columns) {
  write_pose_header(out, PoseColumns{.orientations = columns, .local_transforms = false});
}

void write_poses_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                          std::span<const Eigen::Matrix3d> orientations, std::size_t first_frame,
                          OrientationColumns columns) {
  PoseColumns c;
  if (!orientations.empty()) c.orientations = columns;
  write_pose_rows(
      out, skeleton,
      PoseRows{.positions = positions, .orientations = orientations, .local_rotations = {}, .local_translations = {}},
      first_frame, c);
}

namespace {

// One row's fields, with where each starts (0-based, for the error's column).
struct Field {
  std::string text;
  std::size_t at = 0;
};

// Splits `line` at commas, RFC 4180 quotes allowed; false on a quote left open.
bool split_fields(std::string_view line, std::vector<Field>& out, std::size_t& bad_at) {
  out.clear();
  std::size_t i = 0;
  for (;;) {
    Field f;
    f.at = i;
    if (i < line.size() && line[i] == '"') {
      ++i;
      for (;;) {
        if (i >= line.size()) {
          bad_at = f.at;
          return false;
        }
        if (line[i] == '"') {
          if (i + 1 < line.size() && line[i + 1] == '"') {
            f.text += '"';
            i += 2;
            continue;
          }
          ++i;
          break;
        }
        f.text += line[i++];
      }
      if (i < line.size() && line[i] != ',') {
        bad_at = i;
        return false;
      }
    } else {
      const std::size_t end = std::min(line.find(',', i), line.size());
      f.text = std::string(line.substr(i, end - i));
      i = end;
    }
    out.push_back(std::move(f));
    if (i >= line.size()) return true;
    ++i;  // the comma
  }
}

}  // namespace

Result<PositionsTable> parse_positions_csv(std::string_view text, const std::string& source) {
  PositionsTable t;
  int line_number = 0;
  auto fail = [&](std::size_t column, const std::string& what) {
    Error e = make_error(ErrorKind::kInvalidData, what);
    e.file = source;
    e.line = line_number;
    e.column = static_cast<int>(column + 1);
    return e;
  };
  // 0: positions only; 4: qw,qx,qy,qz; 9: a matrix row by row.
  int orientation_columns = -1;
  std::vector<Field> fields;
  std::size_t row_in_frame = 0;
  std::size_t frame = 0;
  std::size_t start = 0;
  bool first_frame_done = false;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(start, end - start);
    start = end + 1;
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (orientation_columns < 0) {
      if (line == "frame,joint,x,y,z") {
        orientation_columns = 0;
      } else if (line == "frame,joint,x,y,z,qw,qx,qy,qz") {
        orientation_columns = 4;
      } else if (line == "frame,joint,x,y,z,r00,r01,r02,r10,r11,r12,r20,r21,r22") {
        orientation_columns = 9;
      } else {
        return fail(0,
                    "not a positions CSV: the header is 'frame,joint,x,y,z' (with qw,qx,qy,qz or r00..r22 after "
                    "it for orientations)");
      }
      continue;
    }
    if (line.empty()) {
      // Blank lines at the end (the last one may have no line break: start is then past the text).
      if (start >= text.size() || text.substr(start).find_first_not_of("\r\n") == std::string_view::npos) break;
      return fail(0, "an empty row");
    }
    std::size_t bad_at = 0;
    if (!split_fields(line, fields, bad_at)) return fail(bad_at, "a quoted joint name that is not closed");
    const std::size_t want = 5 + static_cast<std::size_t>(orientation_columns);
    if (fields.size() != want) {
      return fail(0, std::to_string(fields.size()) + " fields; the header has " + std::to_string(want));
    }
    std::size_t n = 0;
    const std::string& ft = fields[0].text;
    const auto fr = std::from_chars(ft.data(), ft.data() + ft.size(), n);
    if (ft.empty() || fr.ec != std::errc() || fr.ptr != ft.data() + ft.size()) {
      return fail(fields[0].at, std::string("frame '").append(ft, 0, 32).append("' is not a frame number"));
    }
    double v[14];
    for (std::size_t k = 2; k < want; ++k) {
      const std::string& x = fields[k].text;
      const auto r = std::from_chars(x.data(), x.data() + x.size(), v[k - 2]);
      if (x.empty() || r.ec != std::errc() || r.ptr != x.data() + x.size() || !std::isfinite(v[k - 2])) {
        return fail(fields[k].at, std::string("'").append(x, 0, 32).append("' is not a finite number"));
      }
    }
    const std::string& name = fields[1].text;
    if (t.frames == 0) {  // the first row
      t.first_frame = n;
      frame = n;
      t.frames = 1;
    } else if (n != frame) {
      if (n != frame + 1) {
        return fail(fields[0].at, "frame " + std::to_string(n) + " after frame " + std::to_string(frame) +
                                      ": frames follow one another");
      }
      // The first frame sets the joints; every later one has as many rows.
      if (first_frame_done && row_in_frame != t.joints.size()) {
        return fail(fields[0].at, "frame " + std::to_string(frame) + " has " + std::to_string(row_in_frame) +
                                      " rows; the first frame has " + std::to_string(t.joints.size()));
      }
      first_frame_done = true;
      frame = n;
      ++t.frames;
      row_in_frame = 0;
    }
    if (!first_frame_done) {
      if (name.empty()) return fail(fields[1].at, "an empty joint name");
      if (std::find(t.joints.begin(), t.joints.end(), name) != t.joints.end()) {
        return fail(fields[1].at, "joint '" + name.substr(0, 64) + "' twice in frame " + std::to_string(frame));
      }
      t.joints.push_back(name);
    } else if (row_in_frame >= t.joints.size() || name != t.joints[row_in_frame]) {
      return fail(fields[1].at, "frame " + std::to_string(frame) + " row " + std::to_string(row_in_frame + 1) +
                                    " is '" + name.substr(0, 64) + "'; the first frame has " +
                                    (row_in_frame < t.joints.size() ? "'" + t.joints[row_in_frame] + "'"
                                                                    : std::to_string(t.joints.size()) + " rows"));
    }
    ++row_in_frame;
    t.positions.emplace_back(v[0], v[1], v[2]);
    if (orientation_columns > 0) {
      Eigen::Quaterniond q;
      if (orientation_columns == 4) {
        q = Eigen::Quaterniond(v[3], v[4], v[5], v[6]);
      } else {
        Eigen::Matrix3d r;
        r << v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10], v[11];
        if (!((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-6 && r.determinant() > 0)) {
          return fail(fields[5].at, "the orientation is not a rotation matrix");
        }
        q = Eigen::Quaterniond(r);
      }
      if (!(std::abs(q.norm() - 1.0) < 1e-6)) return fail(fields[5].at, "the quaternion is not of unit length");
      t.orientations.push_back(q.normalized());
    }
  }
  if (orientation_columns < 0) {
    line_number = 1;
    return fail(0, "an empty file: a positions CSV starts with the header 'frame,joint,x,y,z'");
  }
  if (t.frames == 0) return fail(0, "no rows after the header");
  if (row_in_frame != t.joints.size()) {
    return fail(0, "the last frame, " + std::to_string(frame) + ", has " + std::to_string(row_in_frame) +
                       " rows; the first frame has " + std::to_string(t.joints.size()));
  }
  return t;
}

Result<PositionsTable> read_positions_csv(const std::filesystem::path& path) {
  auto text = read_file(path);
  if (!text.ok()) return text.error();
  return parse_positions_csv(*text, path.string());
}

}  // namespace gmr
