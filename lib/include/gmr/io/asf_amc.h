// Acclaim ASF (skeleton) and AMC (motion): owned by the ASF/AMC area.
// Placeholder contract used by load_motion(); the ASF/AMC area replaces it.
#pragma once

#include <filesystem>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Reads an ASF skeleton and an AMC motion and converts them to a GMR
// (pre-rotation) motion: each bone's joint is at the bone's tip, named after
// the bone; the root is `root`.
Result<Motion> read_asf_amc(const std::filesystem::path& asf, const std::filesystem::path& amc,
                            Warnings* out_warnings = nullptr);

}  // namespace gmr
