#include "gmr/core/file_util.h"

#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "core/number_format.h"

namespace gmr {
namespace fs = std::filesystem;

namespace {

Error file_error(const fs::path& path, std::string_view what, int err) {
  Error e;
  e.file = path.string();
  e.message = std::string(what) + ": " + std::strerror(err);
  e.kind = err == ENOENT ? ErrorKind::kNotFound : ErrorKind::kIo;
  return e;
}

// Closes a descriptor on every path out of a function.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

Result<std::string> read_file(const fs::path& path) {
  Fd f;
  f.fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (f.fd < 0) return file_error(path, "cannot open file", errno);
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) return file_error(path, "cannot stat file", errno);
  if (S_ISDIR(st.st_mode)) return file_error(path, "cannot read file", EISDIR);
  // Regular files are read at their stat size (+1 so that EOF shows without a
  // regrow); pipes and files that grow while read double the buffer.
  std::string bytes;
  bytes.resize(S_ISREG(st.st_mode) && st.st_size > 0 ? static_cast<std::size_t>(st.st_size) + 1 : 1 << 16);
  std::size_t len = 0;
  while (true) {
    if (len == bytes.size()) bytes.resize(bytes.size() * 2);
    const ssize_t n = ::read(f.fd, bytes.data() + len, bytes.size() - len);
    if (n < 0) {
      if (errno == EINTR) continue;
      return file_error(path, "cannot read file", errno);
    }
    if (n == 0) break;
    len += static_cast<std::size_t>(n);
  }
  bytes.resize(len);
  return bytes;
}

namespace {

// The temporaries being written, for a signal handler to remove: fixed
// slots, since a handler may not allocate or lock. A slot is free (0),
// being filled (1) or holds a live temporary's path (2).
struct TemporarySlot {
  std::atomic<int> state{0};
  char path[PATH_MAX];
};
TemporarySlot g_temporaries[64];

void track(const fs::path& tmp) {
  const std::string& p = tmp.native();
  if (p.size() >= PATH_MAX) return;  // not removable on a signal; the next write sweeps it
  for (auto& slot : g_temporaries) {
    int free = 0;
    if (slot.state.compare_exchange_strong(free, 1, std::memory_order_acquire)) {
      std::memcpy(slot.path, p.c_str(), p.size() + 1);
      slot.state.store(2, std::memory_order_release);
      return;
    }
  }
}

void untrack(const fs::path& tmp) {
  for (auto& slot : g_temporaries) {
    if (slot.state.load(std::memory_order_acquire) == 2 && tmp.native() == slot.path) {
      slot.state.store(0, std::memory_order_release);
      return;
    }
  }
}

void remove_and_untrack(const fs::path& tmp) {
  ::unlink(tmp.c_str());
  untrack(tmp);
}

// Only async-signal-safe calls: unlink, sigaction, raise.
extern "C" void on_terminating_signal(int sig) {
  for (auto& slot : g_temporaries) {
    if (slot.state.load(std::memory_order_acquire) == 2) ::unlink(slot.path);
  }
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  ::sigaction(sig, &dfl, nullptr);
  ::raise(sig);
}

// Removes ".<name>.tmp.<pid>.<n>" beside `path` when process <pid> is gone
// and the file is over a minute old (a writer on another machine sharing the
// folder has a pid this one cannot see: the age keeps its write safe).
void sweep_stale_temporaries(const fs::path& dir, const std::string& name) {
  const std::string prefix = "." + name + ".tmp.";
  std::error_code ec;
  const auto now = fs::file_time_type::clock::now();
  for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const std::string entry = it->path().filename().string();
    if (entry.size() <= prefix.size() || entry.compare(0, prefix.size(), prefix) != 0) continue;
    const char* p = entry.data() + prefix.size();
    const char* end = entry.data() + entry.size();
    long pid = 0;
    unsigned long n = 0;
    auto r = std::from_chars(p, end, pid);
    if (r.ec != std::errc() || r.ptr == end || *r.ptr != '.' || pid <= 0) continue;
    auto r2 = std::from_chars(r.ptr + 1, end, n);
    if (r2.ec != std::errc() || r2.ptr != end) continue;
    if (pid == ::getpid() || ::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
    std::error_code age_ec;
    const auto written = fs::last_write_time(it->path(), age_ec);
    if (age_ec || now - written < std::chrono::minutes(1)) continue;
    if (!it->is_regular_file(age_ec)) continue;
    fs::remove(it->path(), age_ec);
  }
}

// Phase one of an atomic write: `bytes` in a synced temporary beside `path`
// (same directory, so the rename is atomic), with the permissions of the file
// it will replace. Nothing at `path` changes.
Result<fs::path> write_temporary(const fs::path& path, std::string_view bytes) {
  static std::atomic<unsigned> counter{0};
  if (path.empty() || !path.has_filename()) return file_error(path, "cannot write file", EINVAL);
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  sweep_stale_temporaries(dir, path.filename().string());
  // Unique per process and call.
  std::string tmp_name = ".";
  tmp_name += path.filename().string();
  tmp_name += ".tmp.";
  tmp_name += std::to_string(::getpid());
  tmp_name += '.';
  tmp_name += std::to_string(counter.fetch_add(1));
  const fs::path tmp = dir / tmp_name;
  mode_t mode = 0666;
  struct stat old {};
  const bool replacing = ::stat(path.c_str(), &old) == 0;
  if (replacing && S_ISDIR(old.st_mode)) return file_error(path, "cannot write file", EISDIR);
  if (replacing) mode = old.st_mode & 07777;

  Fd f;
  f.fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode);
  if (f.fd < 0) return file_error(path, "cannot create temporary file in " + dir.string(), errno);
  track(tmp);
  auto fail = [&](std::string_view what, int err) -> Error {
    ::close(f.fd);
    f.fd = -1;
    remove_and_untrack(tmp);
    return file_error(path, what, err);
  };
  if (replacing) (void)::fchmod(f.fd, mode);  // keep the replaced file's permissions (umask would drop some)
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(f.fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return fail("cannot write file", errno);
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(f.fd) != 0) return fail("cannot flush file", errno);
  if (::close(f.fd) != 0) {
    f.fd = -1;
    const int err = errno;
    remove_and_untrack(tmp);
    return file_error(path, "cannot close file", err);
  }
  f.fd = -1;
  return tmp;
}

// Phase two: the temporary replaces `path` (or is removed on failure).
Status rename_into_place(const fs::path& tmp, const fs::path& path) {
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    remove_and_untrack(tmp);
    return file_error(path, "cannot replace file", err);
  }
  untrack(tmp);
  // Make the rename itself durable; failure here leaves a complete file, so it is not reported.
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  Fd d;
  d.fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (d.fd >= 0) (void)::fsync(d.fd);
  return Ok{};
}

}  // namespace

Status write_file_atomic(const fs::path& path, std::string_view bytes) {
  auto tmp = write_temporary(path, bytes);
  if (!tmp) return tmp.error();
  return rename_into_place(*tmp, path);
}

Result<AtomicFileWriter> AtomicFileWriter::open(const fs::path& path, std::string_view head) {
  auto tmp = write_temporary(path, head);
  if (!tmp) return tmp.error();
  AtomicFileWriter w;
  w.path_ = path;
  w.tmp_ = std::move(tmp).value();
  w.size_ = head.size();
  // Not O_APPEND: on Linux pwrite() to such a file appends (patch() needs it not to).
  w.fd_ = ::open(w.tmp_.c_str(), O_WRONLY | O_CLOEXEC);
  if (w.fd_ >= 0 && ::lseek(w.fd_, 0, SEEK_END) < 0) {
    ::close(w.fd_);
    w.fd_ = -1;
  }
  if (w.fd_ < 0) {
    const int err = errno;
    remove_and_untrack(w.tmp_);
    w.tmp_.clear();
    return file_error(path, "cannot reopen its temporary file", err);
  }
  return w;
}

AtomicFileWriter::AtomicFileWriter(AtomicFileWriter&& other) noexcept
    : path_(std::move(other.path_)),
      tmp_(std::exchange(other.tmp_, {})),
      fd_(std::exchange(other.fd_, -1)),
      buffer_(std::move(other.buffer_)),
      size_(other.size_) {}

AtomicFileWriter& AtomicFileWriter::operator=(AtomicFileWriter&& other) noexcept {
  if (this != &other) {
    discard();
    path_ = std::move(other.path_);
    tmp_ = std::exchange(other.tmp_, {});
    fd_ = std::exchange(other.fd_, -1);
    buffer_ = std::move(other.buffer_);
    size_ = other.size_;
  }
  return *this;
}

AtomicFileWriter::~AtomicFileWriter() { discard(); }

void AtomicFileWriter::discard() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!tmp_.empty()) remove_and_untrack(tmp_);
  tmp_.clear();
  buffer_.clear();
}

Status AtomicFileWriter::flush() {
  std::size_t done = 0;
  while (done < buffer_.size()) {
    const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return file_error(path_, "cannot write file", errno);
    }
    done += static_cast<std::size_t>(n);
  }
  buffer_.clear();
  return Ok{};
}

Status AtomicFileWriter::append(std::string_view bytes) {
  if (fd_ < 0) return file_error(path_, "cannot write file", EBADF);
  constexpr std::size_t kBuffer = std::size_t{256} << 10;
  buffer_.append(bytes);
  size_ += bytes.size();
  if (buffer_.size() >= kBuffer) return flush();
  return Ok{};
}

Status AtomicFileWriter::patch(std::size_t offset, std::string_view bytes) {
  if (fd_ < 0) return file_error(path_, "cannot write file", EBADF);
  if (offset + bytes.size() > size_ - buffer_.size()) {
    if (Status s = flush(); !s) return s;
  }
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(offset + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      return file_error(path_, "cannot write file", errno);
    }
    done += static_cast<std::size_t>(n);
  }
  return Ok{};
}

Status AtomicFileWriter::commit() {
  if (fd_ < 0) return file_error(path_, "cannot write file", EBADF);
  if (Status s = flush(); !s) return s;
  if (::fsync(fd_) != 0) return file_error(path_, "cannot flush file", errno);
  const int fd = std::exchange(fd_, -1);
  if (::close(fd) != 0) return file_error(path_, "cannot close file", errno);
  const fs::path tmp = std::exchange(tmp_, {});
  return rename_into_place(tmp, path_);
}

Status write_files_atomic(std::span<const FileContent> files) {
  std::vector<fs::path> temporaries;
  for (const FileContent& f : files) {
    auto tmp = write_temporary(f.path, f.bytes);
    if (!tmp) {
      for (const auto& t : temporaries) remove_and_untrack(t);
      return tmp.error();
    }
    temporaries.push_back(std::move(tmp).value());
  }
  for (std::size_t i = 0; i < files.size(); ++i) {
    if (auto s = rename_into_place(temporaries[i], files[i].path); !s) {
      for (std::size_t k = i + 1; k < files.size(); ++k) remove_and_untrack(temporaries[k]);
      return s;
    }
  }
  return Ok{};
}

void remove_temporaries_on_signals() {
  struct sigaction sa {};
  sa.sa_handler = on_terminating_signal;
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) ::sigaction(sig, &sa, nullptr);
  // Past RLIMIT_FSIZE, write() then fails with EFBIG and the write is undone.
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  ::sigaction(SIGXFSZ, &ignore, nullptr);
}

std::string format_double(double v) {
  char buf[32];
  return std::string(buf, detail::format_shortest(buf, v));
}

Error byte_error(std::string_view file, std::size_t offset, std::string message) {
  Error e;
  e.file = std::string(file);
  e.message = "at byte " + std::to_string(offset) + ": " + std::move(message);
  return e;
}

std::string lower_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

}  // namespace gmr
