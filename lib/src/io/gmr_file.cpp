#include "gmr/io/gmr_file.h"

#include "hierarchy_text.h"

namespace gmr {

Result<Motion> parse_gmr(std::string_view text, std::string_view file_label, Warnings* out_warnings) {
  return detail::parse_hierarchy_text(text, file_label, detail::Dialect::kGmr, out_warnings);
}

Result<Motion> read_gmr(const std::filesystem::path& path, Warnings* out_warnings) {
  return detail::read_hierarchy_file(path, detail::Dialect::kGmr, out_warnings);
}

Result<std::string> format_gmr(const Motion& motion) {
  return detail::format_hierarchy_text(motion, detail::Dialect::kGmr);
}

Status write_gmr(const Motion& motion, const std::filesystem::path& path) {
  return detail::write_hierarchy_file(motion, detail::Dialect::kGmr, path);
}

}  // namespace gmr
