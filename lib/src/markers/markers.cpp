// MarkerTrajectories checks and loading by extension.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <set>

#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/core/file_util.h"
#include "gmr/markers/trc.h"
#include "names.h"

namespace gmr {
namespace detail {

bool make_names_unique(std::vector<std::string>& names) {
  std::set<std::string> used(names.begin(), names.end());
  std::map<std::string, int> count;
  bool renamed = false;
  for (std::string& n : names) {
    int k = ++count[n];
    if (k < 2) continue;
    std::string candidate;
    do candidate = n + "_" + std::to_string(k++);
    while (used.count(candidate));
    used.insert(candidate);
    n = std::move(candidate);
    renamed = true;
  }
  return renamed;
}

}  // namespace detail

std::size_t MarkerTrajectories::missing_points() const {
  std::size_t n = 0;
  for (std::size_t i = 0; i + 2 < positions.size(); i += 3) {
    n += (std::isnan(positions[i]) || std::isnan(positions[i + 1]) || std::isnan(positions[i + 2])) ? 1 : 0;
  }
  return n;
}

Status MarkerTrajectories::validate() const {
  std::set<std::string_view> seen;
  for (const std::string& n : names) {
    if (n.empty()) return make_error("empty marker name");
    if (!seen.insert(n).second) return make_error("duplicate marker name '" + n + "'");
  }
  if (!std::isfinite(frame_rate) || frame_rate < 0) return make_error("frame rate must be finite and >= 0");
  if (!std::isfinite(start_time)) return make_error("start time must be finite");
  if (positions.size() != frame_count * names.size() * 3) {
    return make_error("positions hold " + std::to_string(positions.size()) +
                      " values, expected frames x markers x 3 = " + std::to_string(frame_count * names.size() * 3));
  }
  if (!residuals.empty() && residuals.size() != frame_count * names.size()) {
    return make_error("residuals hold " + std::to_string(residuals.size()) +
                      " values, expected frames x markers = " + std::to_string(frame_count * names.size()));
  }
  for (double v : positions) {
    if (std::isinf(v)) return make_error("infinite marker coordinate");
  }
  return Ok{};
}

bool is_marker_file(const std::filesystem::path& path) {
  const std::string ext = lower_extension(path);
  return ext == ".c3d" || ext == ".trc";
}

Result<MarkerTrajectories> load_markers(const std::filesystem::path& path, Warnings* out_warnings) {
  const std::string ext = lower_extension(path);
  if (ext == ".c3d") return read_c3d(path, out_warnings);
  if (ext == ".trc") return read_trc(path, out_warnings);
  Error e;
  e.file = path.string();
  e.message = "cannot load " + (ext.empty() ? std::string("a file without extension") : "'" + ext + "' files") +
              " as markers: expected .c3d or .trc";
  return e;
}

}  // namespace gmr
