// TRC marker files (OpenSim text): the reader and the writer.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "gmr/core/error.h"
#include "gmr/markers/markers.h"

namespace gmr {

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

}  // namespace gmr
