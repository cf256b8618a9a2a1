// The motions a server serves: loaded from a folder, or the built-in demo.
#pragma once

#include <cstdint>
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
  // 1 when first served; one more each time a reload finds its files changed.
  std::uint32_t version = 1;
  // The size and modification time of the files it was read from (an .amc's
  // skeleton files too, a marker file's model): a reload reads again only
  // entries whose stamp moved.
  std::string stamp;
};

// What library reloads changed, summed (gmr_library_changes_total).
struct LibraryChanges {
  std::uint64_t added = 0, changed = 0, removed = 0;
};

struct Rejection {
  std::filesystem::path path;
  std::string reason;  // the reader's "file:line:column: message"
};

struct LibraryLoad {
  std::vector<LibraryEntry> entries;  // sorted by name
  std::vector<Rejection> rejected;    // sorted by path
  std::size_t skipped = 0;            // files of other kinds (C3D, TRC, text, a lone .asf)
  std::size_t reused = 0;             // reload_library: entries kept from before, their files unchanged
  std::size_t kept_back = 0;          // reload_library: files left as they were (being written, or now unreadable)
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

// The folder again, after `previous` (what load_library or the last reload
// gave). An entry whose files have the same stamp is kept as it is (not read
// again); one whose files changed is read and gets version + 1; a file that
// is in `being_written` (open for writing: half a file is never served), or
// that no longer loads, keeps its previous entry if it had one and counts in
// `kept_back` (rejected files are listed as by load_library); files that are
// gone leave.
Result<LibraryLoad> reload_library(const std::filesystem::path& dir, const std::vector<LibraryEntry>& previous,
                                   const std::vector<std::filesystem::path>& being_written, unsigned threads = 0,
                                   const MotionLimits& limits = {}, const LoadOptions& file_options = {});

// The built-in demo library (gmr/demo/demo_library.h).
std::vector<LibraryEntry> builtin_library();

}  // namespace gmr::server
