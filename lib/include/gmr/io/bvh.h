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
// Never throws; no input crashes it or makes it allocate more than the text
// can hold. Odd but readable input loads and adds a warning to *out_warnings
// (when given):
// - complete frames that do not match `Frames:`: all complete frames load;
// - `Frame Time:` missing or 0: frame_time = 0 (unknown);
// - a joint without OFFSET: 0 0 0.
// Errors (file:line:column, what was expected and what was found): a file that
// ends inside a frame, or has no rows while `Frames:` > 0 (truncated);
// numbers run together (`0.0-7.5`), NaN or infinite values; a CHANNELS count
// that does not match the names; duplicate names or channels; names with
// control characters; joints nested deeper than 1024; a negative frame time.
// Values may wrap across lines; any whitespace separates tokens (tabs, CR, LF,
// CRLF); keywords are case-insensitive; a CHANNELS line after a child JOINT
// is accepted (row columns follow the order of the CHANNELS lines).
Result<Motion> parse_bvh(std::string_view text, std::string_view file_label, Warnings* out_warnings = nullptr);
// Reads and parses a BVH file.
Result<Motion> read_bvh(const std::filesystem::path& path, Warnings* out_warnings = nullptr);

// BVH text of a post-rotation motion (fails for a pre-rotation one: convert it
// first, for a motion that fails validate(), or for a name that could not be
// read back). Numbers are written in their shortest round-tripping form, so
// parse_bvh(format_bvh(m)) has m's values exactly. Each tree is written as one
// ROOT block, depth-first (values permuted to match, so a motion whose joints
// are not in depth-first order reads back in that order with the same values
// per joint name). A non-root leaf without channels is written as a plain
// `End Site` when it has the name the reader would make up for it, else as a
// JOINT with CHANNELS 0 (other readers ignore a name after `End Site`).
// Soft links are not written. Channels are written as they are: for a file
// other programs read the same way, write to_bvh_interchange() of the motion
// (save_motion() does).
Result<std::string> format_bvh(const Motion& motion);
// Writes format_bvh() to `path` atomically (temporary file, then rename).
Status write_bvh(const Motion& motion, const std::filesystem::path& path);

}  // namespace gmr
