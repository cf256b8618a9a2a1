// Acclaim AMC: one motion of an ASF skeleton, frame by frame, read and
// written.
#pragma once

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/acclaim/asf.h"
#include "gmr/core/error.h"

namespace gmr {

struct AmcMotion {
  bool fully_specified = false;          // `:FULLY-SPECIFIED` was present
  bool degrees = true;                   // value unit: :DEGREES / :RADIANS, else the ASF's unit
  std::vector<long long> frame_numbers;  // as written (need not start at 1 or be gapless)
  std::size_t frame_count = 0;
  // Frame-major, skeleton.value_count() per frame, each bone's values at
  // skeleton.value_offset(b) in its dof order; angles in the AMC's unit.
  std::vector<double> values;

  std::span<const double> frame(std::size_t f, std::size_t stride) const {
    return std::span<const double>(values).subspan(f * stride, stride);
  }
};

// Parses AMC text against `skeleton`. Frames are kept in file order. A bone
// with dofs that a frame does not list keeps the value 0 in that frame (its
// rest pose, as CMU's mocapPlayer and amc_parser do) and one warning per file
// says so. Frame numbers that jump (gaps) give a warning. Fails with
// file:line:column for: a bone unknown to the skeleton, a bone listed twice in
// one frame, a wrong number of values, a malformed number, non-finite values,
// data before the first frame number, frame numbers that do not increase, and
// a file with no frame.
Result<AmcMotion> parse_amc(std::string_view text, std::string_view file_label, const AsfSkeleton& skeleton,
                            Warnings* out_warnings = nullptr);
Result<AmcMotion> read_amc(const std::filesystem::path& path, const AsfSkeleton& skeleton,
                           Warnings* out_warnings = nullptr);

// Writes :FULLY-SPECIFIED, the angle unit, then every frame with its number and
// every bone that has dofs. Fails when values does not hold frame_count frames.
Result<std::string> format_amc(const AsfSkeleton& skeleton, const AmcMotion& motion);
// Atomic write (temporary file, then rename).
Status write_amc(const AsfSkeleton& skeleton, const AmcMotion& motion, const std::filesystem::path& path);

}  // namespace gmr
