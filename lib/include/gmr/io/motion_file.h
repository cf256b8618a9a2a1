// Loading and saving a motion by file extension.
//
//   .bvh  BVH (post-rotation)             .gmr  GMR text (pre-rotation)
//   .amc  Acclaim motion; needs the skeleton (.asf) in LoadOptions
//   .gmrb GMR binary (see docs/performance.md), when built in
#pragma once

#include <filesystem>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

struct LoadOptions {
  std::filesystem::path asf;  // skeleton for .amc input; empty: look for a single .asf in the same folder
};

// The motion as the file holds it (BVH and AMC stay post-rotation).
Result<Motion> load_motion(const std::filesystem::path& path, const LoadOptions& options = {},
                           Warnings* out_warnings = nullptr);

// Saves by extension, converting between conventions as needed (.bvh and .amc
// want post-rotation, .gmr/.gmrb pre-rotation). Atomic.
Status save_motion(const Motion& motion, const std::filesystem::path& path, const LoadOptions& options = {});

}  // namespace gmr
