#include "gmr/convert/convert.h"
#include "gmr/io/asf_amc.h"
#include "gmr/io/bvh.h"
#include "gmr/io/gmr_file.h"
#include "gmr/io/gmrb.h"
#include "gmr/io/motion_file.h"
#include "extension.h"

namespace gmr {
namespace {

Error at_path(Error e, const std::filesystem::path& path) {
  if (e.file.empty()) e.file = path.string();
  return e;
}

}  // namespace

Status save_motion(const Motion& motion, const std::filesystem::path& path, const LoadOptions& options) {
  const std::string ext = detail::lower_extension(path);
  if (ext == ".bvh") {
    if (motion.convention == Convention::kPostRotation) return write_bvh(motion, path);
    auto post = to_post_rotation(motion);
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
      return write_asf_amc(*pre, asf, path);
    }
    // ---- .gmrb (GMR binary, PERF area: lib/src/fast/gmrb.cpp)
    return write_gmrb(*pre, path);
  }
  return detail::unknown_extension(path, "write");
}

}  // namespace gmr
