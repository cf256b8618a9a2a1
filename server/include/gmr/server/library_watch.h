// LibraryWatcher: keeps a running server's library in step with its folder
// (docs/protocol.md, "Library reload"). A file under the folder closed after
// writing, moved in or out, or deleted (inotify, on the folder and every
// folder below it) makes it read the folder again once nothing has changed
// for `settle`: reload_library reads only what changed, and the result goes
// to Server::set_library, which ends the streams of motions that changed or
// left. reload() does the same at once (gmr-server calls it on SIGHUP). A
// file still open for writing is never read: it stays as it was until it is
// closed.
#pragma once

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "gmr/server/library.h"

namespace gmr::server {

class Server;

class LibraryWatcher {
 public:
  struct Options {
    std::filesystem::path dir;
    unsigned threads = 0;  // reading files (0: one per core)
    MotionLimits limits;
    LoadOptions file_options;
    double default_metres_per_unit = 0.0;  // for files that declare no unit (--metres-per-unit)
    std::chrono::milliseconds settle{200};
    bool watch = true;  // false: only reload() reads the folder again
  };
  // `loaded`: the entries the server was given (load_library's). Starts
  // watching; when inotify cannot (watch_error()), reload() still works.
  LibraryWatcher(Server& server, Options options, std::vector<LibraryEntry> loaded);
  ~LibraryWatcher();  // stops, and waits for a reload under way
  LibraryWatcher(const LibraryWatcher&) = delete;
  LibraryWatcher& operator=(const LibraryWatcher&) = delete;

  // Reads the folder again now (asynchronously). Thread-safe.
  void reload();
  // Reloads done so far (each read the folder once).
  std::uint64_t reloads() const { return reloads_.load(); }
  // Why the folder is not watched (empty: it is).
  const std::string& watch_error() const { return watch_error_; }

 private:
  void run();
  void watch_tree(const std::filesystem::path& dir);
  void read_events();
  void read_again();

  Server& server_;
  Options options_;
  std::vector<LibraryEntry> current_;
  int inotify_ = -1, wake_ = -1;
  std::string watch_error_;
  struct Watches;
  std::unique_ptr<Watches> watches_;
  std::atomic<std::uint64_t> reloads_{0};
  std::atomic<bool> stopping_{false};
  std::thread thread_;
};

}  // namespace gmr::server
