#include "gmr/io/positions_csv.h"

#include <Eigen/Geometry>

#include <charconv>
#include <string>

#include "core/number_format.h"

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

void write_positions_csv_header(std::ostream& out) { out << "frame,joint,x,y,z\n"; }

void write_positions_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                              std::size_t first_frame) {
  write_poses_csv_rows(out, skeleton, positions, {}, first_frame, OrientationColumns::kQuaternion);
}

void write_poses_csv_header(std::ostream& out, OrientationColumns columns) {
  out << (columns == OrientationColumns::kQuaternion ? "frame,joint,x,y,z,qw,qx,qy,qz\n"
                                                     : "frame,joint,x,y,z,r00,r01,r02,r10,r11,r12,r20,r21,r22\n");
}

void write_poses_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                          std::span<const Eigen::Matrix3d> orientations, std::size_t first_frame,
                          OrientationColumns columns) {
  const std::size_t joints = skeleton.size();
  if (joints == 0) return;
  std::vector<std::string> names;
  names.reserve(joints);
  for (const Joint& j : skeleton.joints()) names.push_back(csv_field(j.name));
  std::string buf;
  buf.reserve(1 << 16);
  const std::size_t frames = positions.size() / joints;
  for (std::size_t f = 0; f < frames; ++f) {
    const std::string frame = std::to_string(first_frame + f);
    for (std::size_t j = 0; j < joints; ++j) {
      const std::size_t k = f * joints + j;
      buf += frame;
      buf += ',';
      buf += names[j];
      for (int i = 0; i < 3; ++i) {
        buf += ',';
        append_number(buf, positions[k][i]);
      }
      if (!orientations.empty()) append_orientation(buf, orientations[k], columns);
      buf += '\n';
    }
    if (buf.size() > (1 << 16) - 1024) {
      out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
      buf.clear();
    }
  }
  out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
}

}  // namespace gmr
