// Marker data: the 3D trajectories of optical (or video) markers, read from
// C3D (binary) and TRC (OpenSim text) files, and written as TRC.
//
// Conventions (docs/markers.md restates them):
// - Positions are kept in the file's units and axes (units says which: "mm",
//   "m", ...); nothing is rotated or rescaled.
// - A missing or invalid point is NaN in all three coordinates, never 0: a
//   C3D point whose residual word is negative, a TRC cell that is blank or
//   spelled NaN in any case.
// - Markers keep the file's order and names (trimmed of padding); analog
//   channels (force plates, EMG) are skipped, only counted.
// - Turning markers into a skeleton motion: gmr/markers/marker_solve.h.
//
// The readers and the writer are in gmr/markers/c3d.h and gmr/markers/trc.h.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"

namespace gmr {

// Trajectories of named markers over evenly spaced frames.
struct MarkerTrajectories {
  std::vector<std::string> names;  // one per marker, file order
  double frame_rate = 0;           // Hz; 0 = unknown
  std::int64_t first_frame = 1;    // number of the first frame in the file (C3D header / TRC Frame# column)
  double start_time = 0;           // seconds at the first frame (TRC Time column; 0 for C3D)
  std::size_t frame_count = 0;
  std::string units;  // "mm", "m", ... as the file says; may be empty
  // frame_count x names.size() x (x, y, z), frame-major; NaN where missing.
  std::vector<double> positions;
  // C3D only: frame_count x names.size() residuals (file units; NaN where the
  // point is invalid). Empty for TRC input.
  std::vector<double> residuals;
  // C3D only: analog channels skipped, and their sample rate (Hz; 0 if none).
  std::size_t analog_channels = 0;
  double analog_rate = 0;

  std::size_t marker_count() const { return names.size(); }
  // Index of (frame, marker, axis) in positions; no bounds check.
  std::size_t index(std::size_t frame, std::size_t marker, int axis = 0) const {
    return (frame * names.size() + marker) * 3 + static_cast<std::size_t>(axis);
  }
  // Number of (frame, marker) points that are missing (NaN).
  std::size_t missing_points() const;
  // Names unique and not empty, sizes consistent (positions and, when
  // present, residuals), no infinite coordinate, frame_rate and start_time
  // finite, frame_rate >= 0. The Error names the broken rule.
  Status validate() const;
};

// Loads by extension, case-insensitively: .c3d or .trc; anything else is an
// error naming the path.
Result<MarkerTrajectories> load_markers(const std::filesystem::path& path, Warnings* out_warnings = nullptr);
// True when `path` has a marker file extension (.c3d or .trc, any case).
bool is_marker_file(const std::filesystem::path& path);

}  // namespace gmr
