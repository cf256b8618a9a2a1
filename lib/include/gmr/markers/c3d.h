// C3D marker files (binary): the reader.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "gmr/core/error.h"
#include "gmr/markers/markers.h"

namespace gmr {

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

}  // namespace gmr
