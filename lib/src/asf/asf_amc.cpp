// ASF and AMC writers. Numbers use the shortest text that reads back to the
// same double, so read -> write -> read is exact.
#include <charconv>
#include <cmath>

#include "acclaim_text.h"
#include "gmr/io/asf_amc.h"
#include "gmr/io/file_util.h"

namespace gmr {

namespace {

void put(std::string& out, double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

void put3(std::string& out, const Eigen::Vector3d& v) {
  put(out, v.x());
  out += ' ';
  put(out, v.y());
  out += ' ';
  put(out, v.z());
}

void put_order(std::string& out, const std::array<Axis, 3>& order) {
  for (Axis a : order) out += static_cast<char>('X' + static_cast<int>(a));
}

}  // namespace

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
    if (p >= 0 && static_cast<std::size_t>(p) < s.bones.size()) children[static_cast<std::size_t>(p)].push_back(static_cast<int>(i));
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

Status write_asf(const AsfSkeleton& skeleton, const std::filesystem::path& path) {
  return write_file_atomic(path, format_asf(skeleton));
}

Status write_amc(const AsfSkeleton& skeleton, const AmcMotion& motion, const std::filesystem::path& path) {
  auto text = format_amc(skeleton, motion);
  if (!text) return text.error();
  return write_file_atomic(path, *text);
}

Status write_asf_amc(const Motion& motion, const std::filesystem::path& asf, const std::filesystem::path& amc) {
  auto model = gmr_to_acclaim(motion);
  if (!model) return model.error();
  // Format both before writing either, so a failure leaves no half-written pair.
  const std::string asf_text = format_asf(model->skeleton);
  auto amc_text = format_amc(model->skeleton, model->motion);
  if (!amc_text) return amc_text.error();
  if (auto s = write_file_atomic(asf, asf_text); !s) return s;
  return write_file_atomic(amc, *amc_text);
}

}  // namespace gmr
