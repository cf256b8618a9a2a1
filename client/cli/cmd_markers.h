// Marker files (.c3d, .trc) in the file commands: `gmr info` and `gmr convert`
// hand them over here; `gmr markers` prints them as CSV.
#pragma once

#include <string>

namespace gmr::cli {

// Prints the marker summary of a .c3d or .trc file (markers, frames, rate,
// units, first frame, missing points, analog channels skipped).
void run_marker_info(const std::string& file);
// Converts a marker file to .trc (atomic write); any other output extension
// is a CommandError.
void run_marker_convert(const std::string& in, const std::string& out);

}  // namespace gmr::cli
