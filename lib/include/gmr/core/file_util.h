// Small file helpers shared by the readers and writers.
#pragma once

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>

#include "gmr/core/error.h"

namespace gmr {

// Whole file as bytes; an Error naming the file (and the system's reason) when
// it cannot be opened or read, or is a directory.
Result<std::string> read_file(const std::filesystem::path& path);

// Writes `bytes` to a temporary file beside `path` (same directory, so the
// rename is atomic), fsyncs it, then renames it over `path`: readers see the
// old file or the new one, never half of one. A replaced file's permission
// bits are kept. On failure the temporary is removed, an existing `path` is
// left as it was, and the Error names `path` and the system's reason. A
// symbolic link at `path` is replaced, not written through.
//
// Temporaries are named ".<name>.tmp.<pid>.<n>". One left by a process that
// died (a SIGKILL, a power cut) is removed by the next write to the same
// `path`: when its process no longer exists and it is over a minute old.
Status write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

// Several files that belong together (an ASF/AMC pair): every one is first
// written to its own synced temporary, and only when all are ready are they
// renamed into place, in the order given. A failure before the renames
// changes nothing at any path; a rename that fails (rare: the temporaries
// are complete and beside their targets) leaves the earlier files replaced
// and the later ones as they were, and the Error names the path.
struct FileContent {
  std::filesystem::path path;
  std::string_view bytes;
};
Status write_files_atomic(std::span<const FileContent> files);

// A file written in pieces, then put in place whole, as write_file_atomic
// puts one (a live recording, whose frames come one by one: nothing of it
// is held in memory but a write buffer). open() makes the temporary beside
// `path` with its first bytes; append() adds to it (buffered); patch()
// overwrites bytes already written (a header's count); commit() flushes,
// syncs and renames it into place. A writer destroyed uncommitted removes
// its temporary, as do the signals remove_temporaries_on_signals() handles.
// Move-only; one thread at a time.
class AtomicFileWriter {
 public:
  static Result<AtomicFileWriter> open(const std::filesystem::path& path, std::string_view head);
  AtomicFileWriter(AtomicFileWriter&& other) noexcept;
  AtomicFileWriter& operator=(AtomicFileWriter&& other) noexcept;
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;
  ~AtomicFileWriter();

  Status append(std::string_view bytes);
  Status patch(std::size_t offset, std::string_view bytes);
  Status commit();
  // Bytes in the file so far (written or buffered).
  std::size_t size() const { return size_; }
  const std::filesystem::path& path() const { return path_; }

 private:
  AtomicFileWriter() = default;
  Status flush();
  void discard();
  std::filesystem::path path_, tmp_;
  int fd_ = -1;
  std::string buffer_;
  std::size_t size_ = 0;
};

// Makes SIGINT, SIGTERM, SIGHUP and SIGQUIT remove the temporaries of the
// writes in progress before the process ends as the signal says, and makes
// a write past the file size limit (SIGXFSZ) an error instead of the end of
// the process. For command-line tools: call once at start. (A SIGKILL cannot
// be caught: the next write sweeps what it leaves.)
void remove_temporaries_on_signals();

// Shortest decimal text that reads back to exactly `v`: the same bytes as
// std::to_chars(first, last, v), only faster for short decimals. E.g.
// "0.1", "-6.101614", "1e-07", "0.30000000000000004".
std::string format_double(double v);

// The extension of `path` with its dot, in lower case (".bvh" for "a.BVH"),
// or "" when it has none: file formats are matched by this.
std::string lower_extension(const std::filesystem::path& path);

// An error in a binary file: "<file>: at byte <offset>: <message>" (the
// .gmrb and C3D readers).
Error byte_error(std::string_view file, std::size_t offset, std::string message);

}  // namespace gmr
