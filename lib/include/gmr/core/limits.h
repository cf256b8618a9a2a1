// The limits every reader applies to the counts a file declares
// (docs/gmr-format.md, "Limits"): one rule for BVH, GMR, .gmrb, ASF/AMC, C3D
// and TRC, so that a few bytes can never make a reader, a conversion or a
// server allocate or compute beyond what the file's bytes justify.
#pragma once

#include <cstdint>
#include <string>

#include "gmr/core/error.h"

namespace gmr {

// Frames in any motion or marker file: 2^24 (39 hours at 120 Hz).
inline constexpr std::uint64_t kMaxFrames = std::uint64_t{1} << 24;
// Frames that carry no bytes in the file (no channels, no markers, no analog
// samples): every such frame is the same, so their count is all a file says
// and it is capped lower, 2^20.
inline constexpr std::uint64_t kMaxEmptyFrames = std::uint64_t{1} << 20;

// Checks a declared frame count: at most kMaxFrames; at most kMaxEmptyFrames
// when `bytes_per_frame` is 0; and, when `bytes_available` is known (binary
// formats), no more frames than those bytes hold. The error (kInvalidData)
// says what was declared and which limit it passed; the caller says where.
Status check_frame_count(std::uint64_t frames, std::uint64_t bytes_per_frame,
                         std::uint64_t bytes_available = UINT64_MAX);

}  // namespace gmr
