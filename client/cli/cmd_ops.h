// The view options of `gmr positions` (--roots, --strip-dummies, --relative-to),
// implemented in cmd_ops.cpp so cmd_files.cpp only forwards to them.
#pragma once

#include <CLI/CLI.hpp>
#include <ostream>
#include <string>

#include "cli_util.h"
#include "gmr/io/positions_csv.h"
#include "gmr/motion/motion.h"
#include "gmr/view/conventions.h"

namespace gmr::cli {

struct ViewOptions {
  std::string roots;  // "A,B,C": the joints that become roots
  bool strip_dummies = false;
  std::string relative_to;  // joint whose frame the coordinates are in
  // An engine's axes and unit (gmr/view/conventions.h), applied last.
  std::string conventions = "native";
  double metres_per_unit = 0.0;  // the motion's unit in metres; 0: unknown
  // Options that change the skeleton or the frame (not the conventions).
  bool any() const { return !roots.empty() || strip_dummies || !relative_to.empty(); }
  Conventions engine() const;
  OutputBasis basis() const;  // throws CommandError for a bad combination
};

// With engine conventions on a motion whose unit nobody gave (not
// --metres-per-unit, not the file or the server: `motion_metres_per_unit`
// 0), warns on stderr that the axes turn but the numbers stay in the
// motion's own units, instead of leaving it silent.
void warn_if_unit_unknown(const ViewOptions& o, double motion_metres_per_unit);

// Registers --roots, --strip-dummies, --relative-to, --conventions and
// --metres-per-unit on `cmd`.
void add_view_options(CLI::App& cmd, ViewOptions& o);

// Writes the positions CSV (header and rows, same contract as plain `gmr
// positions`: rows in the file's joint order, dummies left out when stripped)
// of frames `requested` of the view of `motion`. Throws CommandError for an
// unknown joint or an impossible root set.
// With `orientations` ("quat" or "matrix"; empty: none), each row also has
// the joint's orientation in the view (its GMR bone frame in world or viewer
// coordinates, in the conventions' axes), as `gmr positions --orientations`.
// What `--orientations` (quat, matrix) and `--local-transforms` add to each
// row of gmr positions, query and stream; the two options, on any of them.
PoseColumns pose_columns(const std::string& orientations, bool local_transforms);
void add_pose_options(CLI::App& cmd, std::string& orientations, bool& local_transforms);

void write_view_positions(const Motion& motion, const ViewOptions& o, FrameRange requested, std::ostream& out,
                          const PoseColumns& columns = {});

}  // namespace gmr::cli
