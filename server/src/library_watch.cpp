#include "gmr/server/library_watch.h"

#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/eventfd.h>
#include <sys/inotify.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <set>

#include "gmr/server/server.h"

namespace gmr::server {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// What the watching thread keeps: the folder of each watch, the files open
// for writing, and whether (and from when) the folder is to be read again.
struct LibraryWatcher::Watches {
  std::map<int, fs::path> folders;  // by watch descriptor
  std::set<fs::path> writing;       // modified or created, not closed yet
  bool pending = false;
  Clock::time_point due;
};

namespace {

constexpr std::uint32_t kEvents =
    IN_CLOSE_WRITE | IN_MOVED_TO | IN_MOVED_FROM | IN_DELETE | IN_CREATE | IN_MODIFY | IN_DELETE_SELF;

}  // namespace

LibraryWatcher::LibraryWatcher(Server& server, Options options, std::vector<LibraryEntry> loaded)
    : server_(server),
      options_(std::move(options)),
      current_(std::move(loaded)),
      watches_(std::make_unique<Watches>()) {
  wake_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (options_.watch) {
    inotify_ = ::inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
    if (inotify_ < 0) {
      watch_error_ = std::string("inotify: ") + std::strerror(errno);
    } else {
      watch_tree(options_.dir);
    }
    if (!watch_error_.empty()) {
      spdlog::warn("the library folder is not watched ({}): send SIGHUP to read it again", watch_error_);
    }
  }
  thread_ = std::thread([this] { run(); });
}

LibraryWatcher::~LibraryWatcher() {
  stopping_ = true;
  reload();  // wakes the thread, which sees stopping_
  if (thread_.joinable()) thread_.join();
  if (inotify_ >= 0) ::close(inotify_);
  if (wake_ >= 0) ::close(wake_);
}

void LibraryWatcher::reload() {
  const std::uint64_t one = 1;
  if (wake_ >= 0) (void)::write(wake_, &one, sizeof one);
}

void LibraryWatcher::watch_tree(const fs::path& dir) {
  if (inotify_ < 0) return;
  std::vector<fs::path> folders{dir};
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (it->is_directory(ec)) folders.push_back(it->path());
  }
  for (const auto& f : folders) {
    const int wd = ::inotify_add_watch(inotify_, f.c_str(), kEvents);
    if (wd < 0) {
      // Out of watches (fs.inotify.max_user_watches): the rest is read on SIGHUP.
      if (watch_error_.empty()) watch_error_ = "cannot watch " + f.string() + ": " + std::strerror(errno);
      continue;
    }
    watches_->folders[wd] = f;
  }
}

void LibraryWatcher::read_events() {
  alignas(inotify_event) char buf[16384];
  for (;;) {
    const ssize_t n = ::read(inotify_, buf, sizeof buf);
    if (n <= 0) return;
    for (ssize_t at = 0; at < n;) {
      const auto* e = reinterpret_cast<const inotify_event*>(buf + at);
      at += static_cast<ssize_t>(sizeof(inotify_event) + e->len);
      Watches& w = *watches_;
      if (e->mask & IN_Q_OVERFLOW) {
        w.pending = true;  // events were lost: the folder is read whole anyway
        continue;
      }
      if (e->mask & IN_IGNORED) {
        w.folders.erase(e->wd);
        continue;
      }
      const auto folder = w.folders.find(e->wd);
      if (folder == w.folders.end() || e->len == 0) continue;
      const fs::path path = (folder->second / e->name).lexically_normal();
      if ((e->mask & IN_ISDIR) && (e->mask & (IN_CREATE | IN_MOVED_TO))) {
        watch_tree(path);  // a new folder: watched, and what it holds read
        w.pending = true;
      } else if (e->mask & (IN_CREATE | IN_MODIFY)) {
        w.writing.insert(path);
        continue;  // read once it is closed
      } else if (e->mask & (IN_CLOSE_WRITE | IN_MOVED_TO | IN_MOVED_FROM | IN_DELETE)) {
        w.writing.erase(path);
        w.pending = true;
      } else {
        continue;
      }
      w.due = Clock::now() + options_.settle;  // quiet for `settle` first
    }
  }
}

void LibraryWatcher::run() {
  Watches& w = *watches_;
  while (!stopping_) {
    pollfd fds[2] = {{wake_, POLLIN, 0}, {inotify_, POLLIN, 0}};
    int timeout = -1;
    if (w.pending) {
      timeout = static_cast<int>(
          std::max<Clock::rep>(0, std::chrono::duration_cast<std::chrono::milliseconds>(w.due - Clock::now()).count()));
    }
    const int ready = ::poll(fds, inotify_ >= 0 ? 2 : 1, timeout);
    if (stopping_) break;
    if (ready < 0 && errno != EINTR) {
      spdlog::error("the library watcher stops: poll: {}", std::strerror(errno));
      return;
    }
    // Events first: a file written before reload() was asked is known to be open.
    if (inotify_ >= 0 && (fds[1].revents & POLLIN)) read_events();
    if (fds[0].revents & POLLIN) {
      std::uint64_t n = 0;
      (void)::read(wake_, &n, sizeof n);
      if (stopping_) break;
      w.pending = true;
      w.due = Clock::now();
    }
    if (w.pending && Clock::now() >= w.due) {
      w.pending = false;
      read_again();
    }
  }
}

void LibraryWatcher::read_again() {
  const std::vector<fs::path> writing(watches_->writing.begin(), watches_->writing.end());
  auto loaded =
      reload_library(options_.dir, current_, writing, options_.threads, options_.limits, options_.file_options);
  ++reloads_;
  if (!loaded.ok()) {
    spdlog::error("library reload: {}; the motions served stay", loaded.error().to_string());
    return;
  }
  for (const auto& r : loaded->rejected) spdlog::warn("library reload: rejected {}: {}", r.path.string(), r.reason);
  for (auto& e : loaded->entries) {
    if (e.metres_per_unit == 0.0) e.metres_per_unit = options_.default_metres_per_unit;
  }
  auto same = [](const LibraryEntry& a, const LibraryEntry& b) { return a.name == b.name && a.version == b.version; };
  if (std::equal(loaded->entries.begin(), loaded->entries.end(), current_.begin(), current_.end(), same)) {
    spdlog::debug("library reload: nothing changed ({} files still being written)", writing.size());
    return;
  }
  current_ = loaded->entries;
  server_.set_library(std::move(loaded->entries));
}

}  // namespace gmr::server
