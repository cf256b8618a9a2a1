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

// Parses GMR text (version 1) into a pre-rotation motion. Same warnings,
// errors and limits as parse_bvh() (gmr/io/bvh.h), plus: the version line must
// be `GMR 1`; SOFTLINK only on a ROOT and naming a joint of the file; no End Site.
Result<Motion> parse_gmr(std::string_view text, std::string_view file_label, Warnings* out_warnings = nullptr);
// Reads and parses a .gmr file.
Result<Motion> read_gmr(const std::filesystem::path& path, Warnings* out_warnings = nullptr);

// GMR text of a pre-rotation motion (fails for a post-rotation one, for a
// motion that fails validate(), or for a name that could not be read back).
// Trees are written depth-first with their values permuted to match.
Result<std::string> format_gmr(const Motion& motion);
// Writes format_gmr() to `path` atomically; on failure the old file is intact.
Status write_gmr(const Motion& motion, const std::filesystem::path& path);

}  // namespace gmr
