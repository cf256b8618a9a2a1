// GMR binary (.gmrb): the whole motion in one file that loads with one bulk
// read, for large libraries. Layout in docs/performance.md ("The .gmrb format"):
// a 64-byte little-endian header (magic, version, byte-order mark, sizes), the
// skeleton, then every frame's channel values as IEEE doubles, frame-major,
// exactly Motion::values. Reading what was written gives back the identical
// motion (same joints, offsets, channels, bits of every value).
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include <cstdint>
#include <span>

#include "gmr/core/error.h"
#include "gmr/core/file_util.h"
#include "gmr/motion/motion.h"

namespace gmr {

inline constexpr std::uint32_t kGmrbVersion = 1;

// Every size in the header is checked against the bytes actually present
// before anything is allocated; errors name the file and the byte offset.
Result<Motion> parse_gmrb(std::string_view bytes, std::string_view file_label);
// Reads the header and skeleton, then the values straight into the motion
// (one read of the data section, no intermediate buffer).
Result<Motion> read_gmrb(const std::filesystem::path& path);

// The file's bytes (either convention: the header records which). Fails for an
// invalid motion.
Result<std::string> format_gmrb(const Motion& motion);
// Writes format_gmrb() atomically (temporary file, then rename).
Status write_gmrb(const Motion& motion, const std::filesystem::path& path);

// A .gmrb written a frame at a time (a live recording): the header and the
// skeleton when it opens, each frame's values appended as they come, the
// frame count set and the file put in place by finish() (atomic: `path`
// appears whole or not at all; an appender destroyed unfinished leaves
// nothing). Memory: a write buffer, whatever the length.
class GmrbAppender {
 public:
  // `pattern`: the skeleton, convention and frame time (its values are not
  // written).
  static Result<GmrbAppender> open(const Motion& pattern, const std::filesystem::path& path);
  Status append(std::span<const double> frame);
  // The file in place; its size in bytes.
  Result<std::uint64_t> finish();
  std::uint64_t frames() const { return frames_; }
  std::uint64_t bytes() const { return file_.size(); }
  std::size_t stride() const { return stride_; }
  const std::filesystem::path& path() const { return file_.path(); }

 private:
  explicit GmrbAppender(AtomicFileWriter file, std::size_t stride) : file_(std::move(file)), stride_(stride) {}
  AtomicFileWriter file_;
  std::size_t stride_;
  std::uint64_t frames_ = 0;
};

}  // namespace gmr
