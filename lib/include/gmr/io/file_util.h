// Small file helpers shared by the readers and writers.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "gmr/core/error.h"

namespace gmr {

// Whole file as bytes; an Error naming the file when it cannot be read.
Result<std::string> read_file(const std::filesystem::path& path);

// Writes `bytes` to a temporary file beside `path`, flushes it, then renames it
// over `path`: readers see the old file or the new one, never half of one.
Status write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

// Shortest decimal text that reads back to exactly `v` (std::to_chars).
std::string format_double(double v);

}  // namespace gmr
