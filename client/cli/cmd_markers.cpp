// Marker commands: `gmr markers` (CSV), and the marker side of `gmr info` and
// `gmr convert`.
#include "cmd_markers.h"

#include <cmath>
#include <filesystem>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include "cli_util.h"
#include "commands.h"
#include "gmr/core/file_util.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "gmr/io/positions_csv.h"

namespace gmr::cli {
namespace {

std::string number(double v) {
  if (v == 0.0) v = 0.0;  // one form for -0 and 0
  return format_double(v);
}

// ---- gmr markers

struct MarkersOptions {
  std::string file;
  std::string frames = ":";
};

void run_markers(const MarkersOptions& o) {
  const FrameRange requested = parse_frame_range(o.frames);
  Warnings warnings;
  const MarkerTrajectories d = take(load_markers(o.file, &warnings));
  const FrameRange r = clamp_frame_range(requested, d.frame_count);
  std::vector<std::string> names;
  for (const std::string& n : d.names) names.push_back(csv_field(n));
  std::string out = "frame,marker,x,y,z\n";
  for (std::size_t f = r.begin; f < r.end && d.marker_count() > 0; ++f) {
    const std::string frame = std::to_string(f);
    for (std::size_t m = 0; m < d.marker_count(); ++m) {
      const std::size_t i = d.index(f, m);
      out += frame;
      out += ',';
      out += names[m];
      if (std::isnan(d.positions[i])) {
        out += ",,,\n";  // a missing point: three empty cells
        continue;
      }
      for (int a = 0; a < 3; ++a) {
        out += ',';
        out += number(d.positions[i + static_cast<std::size_t>(a)]);
      }
      out += '\n';
    }
    if (out.size() > (1u << 20)) {
      std::cout.write(out.data(), static_cast<std::streamsize>(out.size()));
      out.clear();
    }
  }
  std::cout.write(out.data(), static_cast<std::streamsize>(out.size()));
  std::cout.flush();
  if (!std::cout) throw CommandError("cannot write the markers to standard output");
  print_warnings(warnings);
}

}  // namespace

void run_marker_info(const std::string& file) {
  Warnings warnings;
  const MarkerTrajectories d = take(load_markers(file, &warnings));
  const std::size_t points = d.frame_count * d.marker_count();
  char rate[64];
  std::snprintf(rate, sizeof rate, "%.6g", d.frame_rate);
  std::string out;
  out += "file:        " + file + "\n";
  out += "markers:     " + std::to_string(d.marker_count()) + "\n";
  out += "frames:      " + std::to_string(d.frame_count) + "\n";
  out += "first frame: " + std::to_string(d.first_frame) + "\n";
  out += d.frame_rate > 0 ? std::string("frame rate:  ") + rate + " Hz\n" : std::string("frame rate:  unknown\n");
  out += "units:       " + (d.units.empty() ? std::string("unknown") : d.units) + "\n";
  char missing[96];
  std::snprintf(missing, sizeof missing, "%zu of %zu points (%.1f%%)", d.missing_points(), points,
                points ? 100.0 * static_cast<double>(d.missing_points()) / static_cast<double>(points) : 0.0);
  out += std::string("missing:     ") + missing + "\n";
  if (d.analog_channels > 0) {
    char analog[96];
    std::snprintf(analog, sizeof analog, "%zu channels at %.6g Hz (not loaded)", d.analog_channels, d.analog_rate);
    out += std::string("analog:      ") + analog + "\n";
  }
  out += "names:      ";
  for (const std::string& n : d.names) out += " " + n;
  out += "\n";
  std::fwrite(out.data(), 1, out.size(), stdout);
  print_warnings(warnings);
}

void run_marker_convert(const std::string& in, const std::string& out) {
  const std::string ext = lower_extension(out);
  if (ext != ".trc") {
    throw CommandError(out + ": cannot write markers as '" + ext + "': expected .trc (markers are not turned into a skeleton)");
  }
  Warnings warnings;
  const MarkerTrajectories d = take(load_markers(in, &warnings));
  check(write_trc(d, out));
  print_warnings(warnings);
}

void add_marker_commands(CLI::App& app) {
  auto o = std::make_shared<MarkersOptions>();
  CLI::App* cmd = app.add_subcommand(
      "markers", "Print a marker file (.c3d, .trc) as CSV: frame,marker,x,y,z (frames from 0, file units, "
                 "missing points as empty cells)");
  cmd->add_option("FILE", o->file, "Marker file (.c3d, .trc)")->required();
  cmd->add_option("--frames", o->frames, "Half-open frame range A:B (frames A to B-1; ':' = all)");
  cmd->callback([o] { run_markers(*o); });
}

}  // namespace gmr::cli
