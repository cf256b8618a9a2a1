#include "gmr/io/motion_file.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <string_view>
#include <system_error>

#include "gmr/acclaim/convert.h"
#include "gmr/ops/convert.h"
#include "gmr/io/bvh.h"
#include "gmr/io/gmr_file.h"
#include "gmr/core/file_util.h"
#include "gmr/io/gmrb.h"

namespace gmr {

namespace {

// "cannot read '.xyz' files: expected .bvh, .gmr, .amc or .gmrb", naming the path.
Error unknown_extension(const std::filesystem::path& path, std::string_view verb) {
  Error e;
  e.file = path.string();
  const std::string ext = lower_extension(path);
  e.message = "cannot " + std::string(verb) + " " +
              (ext.empty() ? std::string("a file without extension") : "'" + ext + "' files") +
              ": expected .bvh, .gmr, .amc or .gmrb";
  return e;
}

// "07" for "07_05-walk" and "07-walk": the CMU subject number before the first '_' or '-'.
std::string subject_of(const std::filesystem::path& p) {
  const std::string stem = p.stem().string();
  return stem.substr(0, stem.find_first_of("_-"));
}

// The skeleton for an AMC: the one given, else the single .asf in its folder,
// else the single one of the same subject (CMU names: 07-walk.asf for
// 07_05-walk.amc).
Result<std::filesystem::path> find_asf(const std::filesystem::path& amc, const LoadOptions& options) {
  if (!options.asf.empty()) return options.asf;
  const std::filesystem::path dir = amc.parent_path().empty() ? std::filesystem::path(".") : amc.parent_path();
  std::vector<std::filesystem::path> found;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (lower_extension(it->path()) == ".asf" && it->is_regular_file(ec)) found.push_back(it->path());
  }
  Error e;
  e.file = amc.string();
  if (ec) {
    e.message = "cannot list " + dir.string() + " to find the .asf skeleton: " + ec.message();
    return e;
  }
  if (found.size() == 1) return found.front();
  std::sort(found.begin(), found.end());
  std::vector<std::filesystem::path> same_subject;
  for (const auto& f : found) {
    if (subject_of(f) == subject_of(amc)) same_subject.push_back(f);
  }
  if (same_subject.size() == 1) return same_subject.front();
  if (found.empty()) {
    e.message = "no .asf skeleton in " + dir.string() + ": name one with --asf";
  } else {
    e.message = "several .asf skeletons in " + dir.string() + " (";
    for (std::size_t i = 0; i < found.size(); ++i) e.message += (i ? ", " : "") + found[i].filename().string();
    e.message += same_subject.empty() ? "), none for subject '" + subject_of(amc) + "': name one with --asf"
                                      : ") for subject '" + subject_of(amc) + "': name one with --asf";
  }
  return e;
}

}  // namespace

Result<Motion> load_motion(const std::filesystem::path& path, const LoadOptions& options, Warnings* out_warnings) {
  const std::string ext = lower_extension(path);
  if (ext == ".bvh") return read_bvh(path, out_warnings);
  if (ext == ".gmr") return read_gmr(path, out_warnings);
  if (ext == ".amc") {
    auto asf = find_asf(path, options);
    if (!asf) return asf.error();
    AcclaimToGmrOptions acclaim;
    if (options.amc_fps != 0.0) {
      if (!std::isfinite(options.amc_fps) || options.amc_fps < 0.0) {
        return Error{.file = path.string(),
                     .message = "the frame rate of an .amc must be a positive number of frames per second"};
      }
      acclaim.frame_time = 1.0 / options.amc_fps;
    }
    return read_asf_amc(*asf, path, out_warnings, acclaim);
  }
  // ---- .gmrb (GMR binary: gmr/io/gmrb.h)
  if (ext == ".gmrb") return read_gmrb(path);
  return unknown_extension(path, "read");
}

double declared_metres_per_unit(const std::filesystem::path& path, const LoadOptions& options) {
  if (lower_extension(path) != ".amc") return 0.0;
  auto asf_path = find_asf(path, options);
  if (!asf_path) return 0.0;
  auto asf = read_asf(*asf_path);
  if (!asf) return 0.0;
  const double length = asf->units.length;
  return std::isfinite(length) && length > 0.0 ? 0.0254 / length : 0.0;
}

std::array<std::filesystem::path, 2> unit_sidecars(const std::filesystem::path& path) {
  std::filesystem::path own = path;
  own.replace_extension(".units");
  return {own, path.parent_path() / "folder.units"};
}

namespace {

constexpr std::size_t kMaxUnitsFileBytes = 4096;

// "0.0254", "in", "centimetres" -> metres per unit; 0 when it names no unit.
double parse_unit(std::string_view word) {
  static const std::pair<std::string_view, double> kNames[] = {
      {"m", 1.0},      {"metre", 1.0},        {"metres", 1.0},        {"meter", 1.0},        {"meters", 1.0},
      {"cm", 0.01},    {"centimetre", 0.01},  {"centimetres", 0.01},  {"centimeter", 0.01},  {"centimeters", 0.01},
      {"mm", 0.001},   {"millimetre", 0.001}, {"millimetres", 0.001}, {"millimeter", 0.001}, {"millimeters", 0.001},
      {"in", 0.0254},  {"inch", 0.0254},      {"inches", 0.0254},     {"ft", 0.3048},        {"foot", 0.3048},
      {"feet", 0.3048}};
  std::string lower(word);
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
  for (const auto& [name, metres] : kNames) {
    if (lower == name) return metres;
  }
  double v = 0;
  const auto r = std::from_chars(word.data(), word.data() + word.size(), v);
  if (r.ec != std::errc() || r.ptr != word.data() + word.size()) return 0.0;
  return std::isfinite(v) && v > 0.0 && v <= 1000.0 ? v : 0.0;
}

Result<double> read_units_file(const std::filesystem::path& path) {
  auto text = read_file(path);
  if (!text.ok()) return text.error();
  if (text->size() > kMaxUnitsFileBytes) {
    return Error{path.string(), 0, 0,
                 "a units file holds one unit; this one has " + std::to_string(text->size()) + " bytes"};
  }
  double found = 0.0;
  int line_no = 0;
  std::string_view rest(*text);
  while (!rest.empty()) {
    const std::size_t eol = rest.find('\n');
    std::string_view line = rest.substr(0, eol);
    rest = eol == std::string_view::npos ? std::string_view() : rest.substr(eol + 1);
    ++line_no;
    line = line.substr(0, line.find('#'));
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string_view::npos) continue;
    line = line.substr(first, line.find_last_not_of(" \t\r") - first + 1);
    std::string said(line.substr(0, 64));  // appended, not concatenated (GCC 12 misreads "'" + s as overlapping)
    if (found != 0.0)
      return Error{path.string(), line_no, 0, "a units file holds one unit; a second line says " + said};
    found = parse_unit(line);
    if (found == 0.0) {
      said.append(" is not a unit: give metres per unit (0.0254) or m, cm, mm, in, ft");
      return Error{path.string(), line_no, 0, said};
    }
  }
  if (found == 0.0) return Error{path.string(), 0, 0, "the units file names no unit"};
  return found;
}

}  // namespace

Result<double> motion_metres_per_unit(const std::filesystem::path& path, const LoadOptions& options) {
  if (const double own = declared_metres_per_unit(path, options); own > 0.0) return own;
  const std::string ext = lower_extension(path);
  if (ext != ".bvh" && ext != ".gmr" && ext != ".gmrb") return 0.0;
  for (const auto& sidecar : unit_sidecars(path)) {
    std::error_code ec;
    if (std::filesystem::is_regular_file(sidecar, ec)) return read_units_file(sidecar);
  }
  return 0.0;
}

// ---- saving ------------------------------------------------------------

namespace {

Error at_path(Error e, const std::filesystem::path& path) {
  if (e.file.empty()) e.file = path.string();
  return e;
}

}  // namespace

Status save_motion(const Motion& motion, const std::filesystem::path& path, const LoadOptions& options) {
  const std::string ext = lower_extension(path);
  if (ext == ".bvh") {
    BvhExportOptions bvh;
    bvh.single_root = options.bvh_single_root;
    auto post = to_bvh_interchange(motion, bvh);
    if (!post) return at_path(post.error(), path);
    return write_bvh(*post, path);
  }
  if (ext == ".gmr" || ext == ".amc" || ext == ".gmrb") {
    Result<Motion> converted = Motion{};
    const Motion* pre = &motion;
    if (motion.convention != Convention::kPreRotation) {
      converted = to_pre_rotation(motion);
      if (!converted) return at_path(converted.error(), path);
      pre = &*converted;
    }
    if (ext == ".gmr") return write_gmr(*pre, path);
    if (ext == ".amc") {
      // The skeleton goes to options.asf, else beside the motion with the same stem.
      std::filesystem::path asf = options.asf;
      if (asf.empty()) asf = std::filesystem::path(path).replace_extension(".asf");
      return write_asf_amc(*pre, asf, path, options.replace_asf);
    }
    // ---- .gmrb (GMR binary: gmr/io/gmrb.h)
    return write_gmrb(*pre, path);
  }
  return unknown_extension(path, "write");
}

}  // namespace gmr
