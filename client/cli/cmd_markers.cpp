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
#include "gmr/io/motion_file.h"
#include "gmr/io/positions_csv.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/marker_frames.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/marker_solve.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "gmr/ops/set_roots.h"

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

// The fit report of `gmr info FILE --model M`: per part, frames fitted,
// interpolated and held, outliers, the fit's RMS and the RMS/max distance
// between measured markers and the markers the motion carries; per joint,
// how it was found and what the take determined.
std::string fit_report(const MarkerSolveResult& r, const std::string& units) {
  std::string out;
  char line[256];
  const std::string u = units.empty() ? std::string("mm") : units;
  std::snprintf(line, sizeof line, "%-11s %7s %7s %6s %8s %10s %12s %10s\n", "part", "fitted", "interp", "held",
                "outliers", "fit rms", "motion rms", "max");
  out += line;
  for (const PartFit& p : r.parts) {
    std::snprintf(line, sizeof line, "%-11s %7zu %7zu %6zu %8zu %10.2f %12.2f %10.2f\n", p.name.c_str(), p.fitted,
                  p.interpolated, p.held, p.outliers, p.fit_rms, p.motion_rms, p.motion_max);
    out += line;
  }
  out += "(distances in " + u + "; motion rms: measured markers against the markers the motion carries)\n";
  std::snprintf(line, sizeof line, "%-11s %-10s %10s %10s %10s %10s %10s %10s\n", "joint", "found by", "determined",
                "from prior", "fit rms", "split", "bone", "bone rms");
  out += line;
  for (const JointFit& j : r.joints) {
    if (j.functional) {
      std::snprintf(line, sizeof line, "%-11s %-10s %8d/3 %10.2f %10.2f %10.2f %10.2f %10.2f\n", j.name.c_str(),
                    "centre", j.determined, j.prior_distance, j.fit_rms, j.split_shift, j.bone_length, j.bone_rms);
    } else {
      std::snprintf(line, sizeof line, "%-11s %-10s %10s %10s %10s %10.2f %10.2f %10.2f\n", j.name.c_str(), "markers",
                    "-", "-", "-", j.split_shift, j.bone_length, j.bone_rms);
    }
    out += line;
  }
  return out;
}

// "cmu41, ...": the built-in models, for messages.
std::string builtin_names() {
  std::string known;
  for (const std::string& n : builtin_marker_model_names()) known += (known.empty() ? "" : ", ") + n;
  return known;
}

MarkerSolveResult solve(const MarkerTrajectories& d, const std::string& model_name, const std::string& roots,
                        Warnings& warnings) {
  const MarkerModel model = take(find_marker_model(model_name));
  MarkerSolveOptions options;
  if (!roots.empty()) options.roots = split_list(roots);
  MarkerSolveResult r = take(solve_markers(d, model, options));
  warnings.insert(warnings.end(), r.warnings.begin(), r.warnings.end());
  return r;
}

}  // namespace

Motion marker_motion(const std::string& file, const std::string& model, double& metres_per_unit, Warnings& warnings) {
  if (model.empty()) {
    throw CommandError(file +
                       ": a marker file gives joint positions through a skeleton model: add --model NAME or "
                       "--model FILE (built in: " +
                       builtin_names() + ")");
  }
  const MarkerTrajectories d = take(load_markers(file, &warnings));
  MarkerSolveResult r = solve(d, model, {}, warnings);
  metres_per_unit = r.millimetres_per_unit / 1000;
  return std::move(r.motion);
}

void run_marker_info(const std::string& file, const std::string& model) {
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
  if (!model.empty()) {
    const MarkerSolveResult r = solve(d, model, {}, warnings);
    out += "model:       " + model + " (" + std::to_string(r.motion.skeleton.size()) + " joints)\n";
    out += fit_report(r, d.units);
  }
  std::fwrite(out.data(), 1, out.size(), stdout);
  print_warnings(warnings);
}

void run_marker_convert(const std::string& in, const std::string& out, const std::string& model,
                        const std::string& roots, double calibrate_seconds) {
  const std::string ext = lower_extension(out);
  if (ext == ".trc") {
    if (!model.empty() || !roots.empty() || calibrate_seconds > 0) {
      throw CommandError(out +
                         ": a .trc output keeps the markers; --model, --roots and --calibrate-seconds make a motion "
                         "(.gmr, .gmrb, .bvh, .amc)");
    }
    Warnings warnings;
    const MarkerTrajectories d = take(load_markers(in, &warnings));
    check(write_trc(d, out));
    print_warnings(warnings);
    return;
  }
  if (model.empty()) {
    throw CommandError(out +
                       ": markers become a motion through a skeleton model: add --model NAME or --model FILE "
                       "(built in: " +
                       builtin_names() + "), or write .trc");
  }
  Warnings warnings;
  const MarkerTrajectories d = take(load_markers(in, &warnings));
  if (!(calibrate_seconds >= 0) || !std::isfinite(calibrate_seconds)) {
    throw CommandError("--calibrate-seconds " + std::to_string(calibrate_seconds) + ": give a number of seconds > 0");
  }
  if (calibrate_seconds == 0) {
    const MarkerSolveResult r = solve(d, model, roots, warnings);
    check(save_motion(r.motion, out));
    print_warnings(warnings);
    return;
  }
  if (!(d.frame_rate > 0)) throw CommandError(in + ": --calibrate-seconds needs the take's frame rate, which it lacks");
  const auto frames = static_cast<std::size_t>(std::ceil(calibrate_seconds * d.frame_rate - 1e-9));
  MarkerFrameCounts counts;
  Motion motion = take(solve_marker_frames(d, take(find_marker_model(model)), 0, frames, &counts));
  if (!roots.empty()) {
    std::vector<int> idx;
    for (const std::string& r : split_list(roots)) {
      const int j = motion.skeleton.find(r);
      if (j < 0) throw CommandError("--roots: unknown joint '" + r + "' (not in marker model " + model + ")");
      idx.push_back(j);
    }
    motion = take(set_roots(motion, idx));
  }
  check(save_motion(motion, out));
  std::fprintf(stderr,
               "calibrated on frames 0-%zu; solved %zu frames one at a time (%zu refused, repeating the one before), "
               "%zu part poses held, %zu points left out as outliers, %zu missing\n",
               std::min(frames, d.frame_count) - 1, counts.solved, counts.refused, counts.held, counts.outliers,
               counts.missing);
  print_warnings(warnings);
}

void add_marker_commands(CLI::App& app) {
  auto o = std::make_shared<MarkersOptions>();
  CLI::App* cmd =
      app.add_subcommand("markers",
                         "Print a marker file (.c3d, .trc) as CSV: frame,marker,x,y,z (frames from 0, file units, "
                         "missing points as empty cells)");
  cmd->add_option("FILE", o->file, "Marker file (.c3d, .trc)")->required();
  cmd->add_option("--frames", o->frames, "Half-open frame range A:B (frames A to B-1; ':' = all)");
  cmd->callback([o] { run_markers(*o); });
}

}  // namespace gmr::cli
