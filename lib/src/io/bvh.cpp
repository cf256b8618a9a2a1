#include "gmr/io/bvh.h"

#include "gmr/io/file_util.h"
#include "hierarchy_text.h"

namespace gmr {

Result<Motion> parse_bvh(std::string_view text, std::string_view file_label, Warnings* out_warnings) {
  return detail::parse_hierarchy_text(text, file_label, detail::Dialect::kBvh, out_warnings);
}

Result<Motion> read_bvh(const std::filesystem::path& path, Warnings* out_warnings) {
  auto text = read_file(path);
  if (!text) return text.error();
  return parse_bvh(*text, path.string(), out_warnings);
}

Result<std::string> format_bvh(const Motion& motion) {
  return detail::format_hierarchy_text(motion, detail::Dialect::kBvh);
}

Status write_bvh(const Motion& motion, const std::filesystem::path& path) {
  // Format first: a motion that cannot be written leaves the old file alone.
  auto text = format_bvh(motion);
  if (!text) {
    Error e = text.error();
    if (e.file.empty()) e.file = path.string();
    return e;
  }
  return write_file_atomic(path, *text);
}

}  // namespace gmr
