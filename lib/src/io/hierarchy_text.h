// Private: the reader and writer shared by BVH and the GMR text format, which
// have the same shape (a HIERARCHY of ROOT/JOINT blocks, then MOTION rows).
// The two dialects differ only in the version line, End Site (BVH only),
// SOFTLINK (GMR only) and the convention the values are in.
#pragma once

#include <filesystem>

#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr::detail {

enum class Dialect { kBvh, kGmr };

// Current (and only) version of the GMR text format written by
// format_hierarchy_text(kGmr) and accepted by the reader.
inline constexpr int kGmrFormatVersion = 1;

Result<Motion> parse_hierarchy_text(std::string_view text, std::string_view file_label, Dialect dialect,
                                    Warnings* out_warnings);

Result<std::string> format_hierarchy_text(const Motion& motion, Dialect dialect);

// Reads `path` and parses it; errors name the file.
Result<Motion> read_hierarchy_file(const std::filesystem::path& path, Dialect dialect, Warnings* out_warnings);

// Formats first, then writes atomically: a motion that cannot be written
// leaves the old file alone. Errors without a file name get `path`.
Status write_hierarchy_file(const Motion& motion, Dialect dialect, const std::filesystem::path& path);

// Joint indices in the order a file writes them: each root (in index order)
// followed by its subtree, depth first, children in index order.
std::vector<int> depth_first_order(const Skeleton& skeleton);

// Name an unnamed BVH `End Site` under `parent_name` gets, given a predicate
// telling which names are taken so far: `<parent>_End`, else `<parent>_End2`,
// `_End3`, ... (the first free one). `next_k` is per parent, starts at 1 and
// is advanced past the suffix returned: names are never released, so earlier
// suffixes stay taken, and many End Sites under one parent cost linear time.
template <class Taken>
std::string default_end_site_name(std::string_view parent_name, Taken taken, int& next_k) {
  const std::string base = std::string(parent_name) + "_End";
  for (;; ++next_k) {
    std::string n = next_k <= 1 ? base : base + std::to_string(next_k);
    if (!taken(n)) {
      ++next_k;
      return n;
    }
  }
}

}  // namespace gmr::detail
