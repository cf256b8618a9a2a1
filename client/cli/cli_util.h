// Helpers shared by the subcommands: how a command fails, warnings, file
// extensions, and frame ranges.
#pragma once

#include <cstddef>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/core/file_util.h"
#include "gmr/core/names.h"
#include "gmr/motion/motion.h"

namespace gmr::cli {

// Thrown by a subcommand to stop with exit status 1 and print `what()` as the
// single line on stderr. main() catches it.
struct CommandError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Unwraps a Result or throws CommandError with the error's "file:line:col: message".
template <class T>
T take(Result<T> r) {
  if (!r.ok()) throw CommandError(r.error().to_string());
  return std::move(r).value();
}
inline void check(const Status& s) {
  if (!s.ok()) throw CommandError(s.error().to_string());
}

// Half-open frame range "A:B" (either side may be empty: ":B", "A:", ":").
struct FrameRange {
  std::size_t begin = 0;
  std::size_t end = static_cast<std::size_t>(-1);
};
// Parses "A:B"; throws CommandError on anything else. Clamps nothing.
FrameRange parse_frame_range(std::string_view text);
// The frames of `r` in a motion of frame_count frames: an open end becomes
// frame_count; a range that is empty or reaches past the last frame throws
// CommandError, as the protocol refuses it (QueryFrames). Nothing is clamped.
FrameRange clamp_frame_range(FrameRange r, std::size_t frame_count);

// Prints a reader's warnings on stderr, one "gmr: warning: ..." line each
// (after the command's output; a failing command prints only its error line).
void print_warnings(const Warnings& warnings);

// A motion file (gmr::load_motion) with an .amc's --asf and --fps; throws
// CommandError on a bad file, appends the reader's warnings.
Motion load(const std::string& file, const std::string& asf, double fps, Warnings& warnings);

// The extension of `path` in lower case: gmr::lower_extension.
using ::gmr::lower_extension;

// Indentation of a joint at `depth` in a printed tree: two spaces a level up
// to 32 levels, then "[depth N] " so a deep chain prints in linear size.
std::string tree_indent(int depth);

// Text from another program (a server's names and reasons, a beacon) as
// printed: control, invisible and bidirectional characters escaped.
inline std::string shown(std::string_view text) { return terminal_safe(text); }

// Splits "A,B,C" into names (empty items are an error).
std::vector<std::string> split_list(std::string_view text);

}  // namespace gmr::cli
