// Marker files (.c3d, .trc) in the file commands: `gmr info` and `gmr convert`
// hand them over here; `gmr markers` prints them as CSV.
#pragma once

#include <string>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr::cli {

// The motion a marker file and a skeleton model (a built-in name or a model
// file) give (gmr/markers/marker_solve.h); `metres_per_unit` gets the marker
// file's unit. Reader and solver warnings are appended to `warnings`.
Motion marker_motion(const std::string& file, const std::string& model, double& metres_per_unit, Warnings& warnings);

// Prints the marker summary of a .c3d or .trc file (markers, frames, rate,
// units, first frame, missing points, analog channels skipped) and, with a
// skeleton model (a built-in name or a model file), the fit report.
void run_marker_info(const std::string& file, const std::string& model);
// Converts a marker file: to .trc (atomic write), or with a skeleton model to
// a motion (.gmr, .gmrb, .bvh, .amc) whose roots are `roots` (A,B; empty:
// the model's). A motion output without a model is a CommandError.
// `calibrate_seconds` > 0: solved frame by frame as a live source is, on a
// calibration of the take's first seconds (gmr/markers/marker_frames.h).
void run_marker_convert(const std::string& in, const std::string& out, const std::string& model,
                        const std::string& roots, double calibrate_seconds = 0.0);

}  // namespace gmr::cli
