#include "gmr/io/bvh.h"

#include "hierarchy_text.h"

namespace gmr {

Result<Motion> parse_bvh(std::string_view text, std::string_view file_label, Warnings* out_warnings) {
  return detail::parse_hierarchy_text(text, file_label, detail::Dialect::kBvh, out_warnings);
}

Result<Motion> read_bvh(const std::filesystem::path& path, Warnings* out_warnings) {
  return detail::read_hierarchy_file(path, detail::Dialect::kBvh, out_warnings);
}

Result<std::string> format_bvh(const Motion& motion) {
  return detail::format_hierarchy_text(motion, detail::Dialect::kBvh);
}

Status write_bvh(const Motion& motion, const std::filesystem::path& path) {
  return detail::write_hierarchy_file(motion, detail::Dialect::kBvh, path);
}

}  // namespace gmr
