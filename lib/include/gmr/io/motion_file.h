// Loading and saving a motion by file extension.
//
//   .bvh  BVH (post-rotation)             .gmr  GMR text (pre-rotation)
//   .amc  Acclaim motion; its skeleton (.asf) from LoadOptions, else the single
//         .asf in the .amc's folder, else the single one there whose name starts
//         with the same subject ("07-walk.asf" for "07_05-walk.amc": the text
//         before the first '_' or '-'); an error if there is none or several
//   .gmrb GMR binary (see docs/performance.md), when built in
// Extensions are matched case-insensitively; any other is an error.
#pragma once

#include <array>
#include <filesystem>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

struct LoadOptions {
  std::filesystem::path asf;  // skeleton for .amc input; empty: look for it in the same folder (above)
  // Frames per second of .amc input (AMC files do not say): 0 means 120, the
  // rate of the CMU captures. Other formats carry their own.
  double amc_fps = 0.0;
  // Saving .amc: an existing skeleton file with other content is replaced
  // only when this is true (otherwise the save fails and writes nothing).
  bool replace_asf = false;
  // Saving .bvh: a forest is written as one ROOT (BvhExportOptions::single_root)
  // for readers that take only one; otherwise one ROOT block per tree.
  bool bvh_single_root = false;
};

// The motion as the file holds it: BVH stays post-rotation, GMR is
// pre-rotation, AMC comes converted to pre-rotation by read_asf_amc().
Result<Motion> load_motion(const std::filesystem::path& path, const LoadOptions& options = {},
                           Warnings* out_warnings = nullptr);

// The unit a motion file declares, in metres per unit, or 0 when it declares
// none. Only Acclaim skeletons do: CMU's ASF lengths are inches divided by
// `units length` (0.45 in every CMU file), so an .amc's unit is
// 0.0254 / length of its .asf (found as load_motion finds it). BVH, GMR and
// GMRB carry no unit. Never fails: an unreadable skeleton declares nothing.
double declared_metres_per_unit(const std::filesystem::path& path, const LoadOptions& options = {});

// Where the unit of a motion file that carries none (.bvh, .gmr, .gmrb) may be
// declared beside it: X.units for X.bvh, else folder.units for every such file
// of its folder (docs/protocol.md, "Units"). Both paths, present or not.
std::array<std::filesystem::path, 2> unit_sidecars(const std::filesystem::path& path);

// The unit of a motion file in metres per unit: what the file declares
// (declared_metres_per_unit), else what its nearest sidecar says, else 0
// (unknown). A sidecar holds one unit: a number of metres per unit (0.0254) or
// a name (m, cm, mm, in, ft and their long forms); '#' starts a comment. An
// unreadable or malformed sidecar is an error naming it and the line.
Result<double> motion_metres_per_unit(const std::filesystem::path& path, const LoadOptions& options = {});

// Saves by extension, converting between conventions as needed (.bvh wants
// post-rotation, and gets the form every common reader reads alike:
// to_bvh_interchange; .gmr, .gmrb and .amc pre-rotation). Atomic. For .amc the
// skeleton is written to options.asf, else beside it with the extension .asf,
// the two as a pair (write_asf_amc); an existing skeleton that differs is
// kept, and the save refused, unless options.replace_asf.
Status save_motion(const Motion& motion, const std::filesystem::path& path, const LoadOptions& options = {});

}  // namespace gmr
