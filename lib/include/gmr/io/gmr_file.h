// The GMR text format (.gmr), documented in docs/gmr-format.md: a version
// line, a hierarchy of one or more ROOTs (each joint with OFFSET, CHANNELS and
// an optional SOFTLINK), then MOTION with one row of channel values per frame.
// Reading what was written gives back the identical motion.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

Result<Motion> parse_gmr(std::string_view text, std::string_view file_label, Warnings* out_warnings = nullptr);
Result<Motion> read_gmr(const std::filesystem::path& path, Warnings* out_warnings = nullptr);

// GMR text of a pre-rotation motion (fails for a post-rotation one).
Result<std::string> format_gmr(const Motion& motion);
Status write_gmr(const Motion& motion, const std::filesystem::path& path);

}  // namespace gmr
