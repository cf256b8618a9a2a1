#include "gmr/io/motion_file.h"

#include <algorithm>
#include <cctype>
#include <cmath>
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
        Error e;
        e.file = path.string();
        e.message = "the frame rate of an .amc must be a positive number of frames per second";
        return e;
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
