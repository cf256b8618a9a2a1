// The log lines connections cause (connected, closed, bad bytes, timeouts,
// Hello), within one server-wide budget: a client that connects, sends 4
// bad bytes and closes in a loop wrote about 300 bytes of log per
// connection, 4.2 MB/s from one process. Past kBurst lines a second the
// rest are counted, and the next line logged says how many were left out
// (also gmr_log_lines_suppressed_total).
#pragma once

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cstdint>
#include <mutex>
#include <string>
#include <utility>

#include "transport/net.h"

namespace gmr::server {

class ConnectionLog {
 public:
  static constexpr std::size_t kBurst = 50;

  // True when a line may be logged now; `suppressed` then says how many were not since.
  bool allow(std::uint64_t& suppressed) {
    std::lock_guard lock(mutex_);
    const bool ok = limiter_.allow(suppressed);
    if (!ok) ++suppressed_total_;
    return ok;
  }
  std::uint64_t suppressed_total() const {
    std::lock_guard lock(mutex_);
    return suppressed_total_;
  }

 private:
  mutable std::mutex mutex_;
  LogLimiter limiter_{kBurst, std::chrono::seconds(1)};
  std::uint64_t suppressed_total_ = 0;
};

// The process's one budget (connections run on every I/O thread).
ConnectionLog& connection_log();

// Logs a line about one connection within the budget.
template <class... Args>
void log_connection(spdlog::level::level_enum level, fmt::format_string<Args...> format, Args&&... args) {
  if (!spdlog::should_log(level)) return;
  std::uint64_t suppressed = 0;
  if (!connection_log().allow(suppressed)) return;
  std::string line = fmt::format(format, std::forward<Args>(args)...);
  if (suppressed != 0) line += fmt::format(" ({} connection lines suppressed before this one)", suppressed);
  spdlog::log(level, "{}", line);
}

}  // namespace gmr::server
