// Helpers shared by the IO tests.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>

#include "gmr/motion/motion.h"

namespace gmr::test {

// Debug and sanitizer builds run the same checks on fewer frames (forward
// kinematics of every frame of the corpus takes minutes there); Release
// builds check every frame. Parsing and value comparisons always cover every
// frame.
#if defined(GMR_SANITIZED) || !defined(NDEBUG)
inline constexpr bool kSlowBuild = true;
inline constexpr std::size_t kMaxFramesForPositions = 40;
#else
inline constexpr bool kSlowBuild = false;
inline constexpr std::size_t kMaxFramesForPositions = std::numeric_limits<std::size_t>::max();
#endif

// `m` with at most `max_frames` frames, evenly spaced, first and last kept.
inline Motion sample_frames(const Motion& m, std::size_t max_frames = kMaxFramesForPositions) {
  if (m.frame_count <= max_frames || max_frames < 2) return m;
  Motion out;
  out.skeleton = m.skeleton;
  out.convention = m.convention;
  out.frame_time = m.frame_time;
  out.frame_count = max_frames;
  out.values.reserve(max_frames * m.stride());
  for (std::size_t i = 0; i < max_frames; ++i) {
    const std::size_t f = i * (m.frame_count - 1) / (max_frames - 1);
    const auto row = m.frame(f);
    out.values.insert(out.values.end(), row.begin(), row.end());
  }
  return out;
}

}  // namespace gmr::test
