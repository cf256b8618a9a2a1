// The motions a server serves: loaded from a folder, or the built-in demo.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "gmr/io/motion_file.h"
#include "gmr/motion/motion.h"

namespace gmr::server {

struct LibraryEntry {
  std::string name;                      // unique: path relative to the folder without extension, '/'-separated
  std::string source;                    // the file it came from, relative to the library folder, or "builtin"
  std::shared_ptr<const Motion> motion;  // pre-rotation (GMR), validated
  double metres_per_unit = 0.0;          // the motion's unit in metres (conventions); 0: unknown
};

struct Rejection {
  std::filesystem::path path;
  std::string reason;  // the reader's "file:line:column: message"
};

struct LibraryLoad {
  std::vector<LibraryEntry> entries;  // sorted by name
  std::vector<Rejection> rejected;    // sorted by path
  std::size_t skipped = 0;            // files of other kinds (C3D, TRC, text, a lone .asf)
};

// What one motion may cost the server. Everything it serves scales with
// frames x joints (positions, the float form) or with its values; a motion
// above either limit is rejected at load with the figures, so that no request
// can later make the server compute or allocate on its behalf beyond them.
struct MotionLimits {
  std::uint64_t max_joint_frames = std::uint64_t{1} << 25;   // frames x joints (CMU: 31 joints x 1 M frames)
  std::uint64_t max_value_bytes = std::uint64_t{512} << 20;  // frames x channels x 8
};
// Ok, or an error with the figures and the limit passed.
Status check_motion_limits(const Motion& m, const MotionLimits& limits);

// Progress: called from worker threads (serialised) after each file.
using LoadProgress = std::function<void(std::size_t done, std::size_t total, const std::filesystem::path& file,
                                        const std::string* rejection_reason)>;

// Loads every .bvh, .gmr, .gmrb and .amc (with the .asf of its folder: the only
// one, or the one whose stem prefixes the .amc's) under `dir`, recursively, on
// `threads` threads (0: hardware concurrency). Never stops at a bad file: it is
// listed in `rejected` with the reason. Each motion is converted to
// pre-rotation and checked against `limits`. `file_options` applies to every file
// (amc_fps: the frame rate of .amc files, which do not hold one). Fails only
// when `dir` is not a readable folder.
Result<LibraryLoad> load_library(const std::filesystem::path& dir, unsigned threads = 0,
                                 const LoadProgress& progress = {}, const MotionLimits& limits = {},
                                 const LoadOptions& file_options = {});

// The built-in demo library (gmr/demo/demo_library.h).
std::vector<LibraryEntry> builtin_library();

}  // namespace gmr::server
