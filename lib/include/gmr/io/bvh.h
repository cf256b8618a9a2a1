// BVH reader and writer.
//
// Conventions (docs/gmr-format.md restates them):
// - The motion is returned as it is in the file: Convention::kPostRotation,
//   joints in file order, channel values in file order (degrees, file units).
// - Euler channels compose in listed order; position channels replace the
//   OFFSET component of their axis, on the root and on any other joint.
// - An End Site becomes a leaf joint with no channels named `<parent>_End`
//   (a second one under the same parent `<parent>_End2`, ...), or the name
//   written after `End Site` when there is one.
// - Several ROOT blocks give a forest.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Parses BVH text. `file_label` names the source in errors ("file:line:col: ...").
// Odd but readable input (a frame count that does not match the rows, a zero
// frame time) loads and adds a warning to *out_warnings when given.
Result<Motion> parse_bvh(std::string_view text, std::string_view file_label, Warnings* out_warnings = nullptr);
// Reads and parses a BVH file.
Result<Motion> read_bvh(const std::filesystem::path& path, Warnings* out_warnings = nullptr);

// BVH text of a post-rotation motion (fails for a pre-rotation one: convert it
// first). Numbers are written in their shortest round-tripping form.
Result<std::string> format_bvh(const Motion& motion);
// Writes format_bvh() to `path` atomically (temporary file, then rename).
Status write_bvh(const Motion& motion, const std::filesystem::path& path);

}  // namespace gmr
