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
// - Turning markers into a skeleton is not done here (not supported yet).
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

// Parses C3D bytes. `file_label` names the source in errors, which read
// "file: at byte N: what". Never throws; every size and offset read from the
// file is checked against the bytes present before it is used or allocated.
// Reads Intel (little-endian), DEC (little-endian, VAX floats, converted) and
// MIPS (big-endian) files, integer and float point storage (negative
// POINT:SCALE). The parameter section decides over the header: POINT:USED,
// POINT:FRAMES (int or float; TRIAL:ACTUAL_START/END_FIELD when present),
// POINT:RATE, POINT:DATA_START, POINT:LABELS + LABELS2..., POINT:UNITS.
// Warnings (when out_warnings is given): header and parameters disagree on
// the point count, data start or analog size; labels missing for some points
// (named "Point<N>") or repeated (suffixed _2, _3, ...); a frame rate that is
// not usable (set to 0); a file that ends before the declared frames (the
// whole frames present are loaded).
// Errors: not a C3D file, an unknown processor type, a parameter record that
// runs past the end of the file or has a bad type, a data section that starts
// inside the parameters or past the end, implausible point or frame counts.
Result<MarkerTrajectories> parse_c3d(std::string_view bytes, std::string_view file_label,
                                     Warnings* out_warnings = nullptr);
// Reads and parses a C3D file.
Result<MarkerTrajectories> read_c3d(const std::filesystem::path& path, Warnings* out_warnings = nullptr);

// Parses TRC text. `file_label` names the source in errors
// ("file:line:column: what"). Accepts LF, CRLF or CR line ends; cells
// separated by tabs (blank cells allowed), commas, or runs of spaces (decided
// by the first line); 7 or 8 header keys in any order; marker names from the
// fourth line; coordinate labels starting at X0, X1 or any other number;
// blank cells and NaN in any case as missing; E-notation; frame numbers that
// do not start at 1; blank lines (or lines of empty cells) between rows.
// Warnings: NumFrames or NumMarkers that do not match what the file holds
// (what is there is loaded), a Time more than 0.1 frame off DataRate, gaps in
// the frame numbers, repeated marker names (later ones get _2, _3, ...).
// Errors: a missing header line, a row with too few or too many values (a
// truncated last row included), a value that is not a number, infinite
// values.
Result<MarkerTrajectories> parse_trc(std::string_view text, std::string_view file_label,
                                     Warnings* out_warnings = nullptr);
// Reads and parses a TRC file.
Result<MarkerTrajectories> read_trc(const std::filesystem::path& path, Warnings* out_warnings = nullptr);

// TRC text (tab-separated, LF line ends, 8 header keys, X1 Y1 Z1 ...): every
// number in its shortest round-tripping form, NaN written "NaN", Time =
// start_time + i / frame_rate (start_time + i when the rate is unknown), so
// parse_trc(format_trc(d)) has d's positions bit for bit. `file_name` goes on
// the PathFileType line ("markers.trc" when empty). Fails for data that fails
// validate() or has names with tabs, line breaks or spaces at either end.
Result<std::string> format_trc(const MarkerTrajectories& data, std::string_view file_name = {});
// Writes format_trc() to `path` atomically (temporary file, then rename).
Status write_trc(const MarkerTrajectories& data, const std::filesystem::path& path);

// Loads by extension, case-insensitively: .c3d or .trc; anything else is an
// error naming the path.
Result<MarkerTrajectories> load_markers(const std::filesystem::path& path, Warnings* out_warnings = nullptr);
// True when `path` has a marker file extension (.c3d or .trc, any case).
bool is_marker_file(const std::filesystem::path& path);

}  // namespace gmr
