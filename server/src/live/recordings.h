// Recordings: live sources' frames streamed to disk as they are accepted
// (docs/protocol.md, "Recording"), bounded in sum, and put in place when the
// source ends.
//
// A Recording appends each frame to a temporary .gmrb beside its file
// (GmrbAppender: nothing of it is held in memory but a write buffer); when
// its source ends, Recordings finishes it off the control loop (the frame
// count, fsync, rename: a file appears whole or not at all), and the server
// waits for the finishes still running when it stops.
//
// RecordBudget bounds what recordings take, in 1 MiB steps: the bytes of
// the recordings being written against --max-record-total-bytes, those and
// the record directory's files against --max-record-dir-bytes, and the
// disk's free space (kFreeReserve always left). A recording that meets a
// bound stops growing there (the file keeps what came before); a new one
// that cannot take its first step is refused. Both are counted and logged.
#pragma once

#include <atomic>
#include <cstdint>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "gmr/io/gmrb.h"
#include "gmr/server/config.h"
#include "transport/net.h"

namespace gmr::server {

class RecordBudget {
 public:
  static constexpr std::uint64_t kStep = std::uint64_t{1} << 20;
  static constexpr std::uint64_t kFreeReserve = std::uint64_t{256} << 20;
  explicit RecordBudget(const ServerConfig& cfg) : cfg_(cfg) {}

  // Why a new recording may not start now (empty: it may, and its first
  // step is taken): measures the record directory and the disk first.
  std::string admit();
  // Takes `bytes` more for a recording under way (false: past a bound).
  bool take(std::uint64_t bytes);
  // A recording gave up `held` bytes: nothing was kept, or its file of
  // `file_bytes` is now in the directory.
  void release(std::uint64_t held, std::uint64_t file_bytes);
  void count_cut() { ++cut_; }

  std::uint64_t held() const;
  std::uint64_t refused() const;
  std::uint64_t cut() const { return cut_; }

 private:
  std::string bound_passed(std::uint64_t more) const;  // locked
  const ServerConfig& cfg_;
  mutable std::mutex m_;
  std::uint64_t held_ = 0;       // by recordings being written
  std::uint64_t dir_bytes_ = 0;  // the directory's files, as last measured plus those finished since
  std::uint64_t refused_ = 0;
  std::atomic<std::uint64_t> cut_{0};
};

// One live source's recording. Touched on the control loop, then handed to
// Recordings::finish.
class Recording {
 public:
  // `file`: the appender; `max_bytes`: --max-record-bytes of values; the
  // first step of `budget` is already taken (RecordBudget::admit).
  Recording(GmrbAppender file, std::uint64_t max_bytes, RecordBudget& budget, std::string name);
  ~Recording();
  Recording(const Recording&) = delete;
  Recording& operator=(const Recording&) = delete;

  // Appends one accepted frame, unless the recording was cut (at its own
  // limit, the budget, or a write error: logged once).
  void add(std::span<const double> values);
  std::uint64_t frames() const { return file_ ? file_->frames() : 0; }
  bool cut() const { return !why_cut_.empty(); }
  const std::string& why_cut() const { return why_cut_; }

 private:
  friend class Recordings;
  void stop(std::string why);
  std::optional<GmrbAppender> file_;
  std::uint64_t max_bytes_;
  RecordBudget& budget_;
  std::string name_;
  std::uint64_t held_ = RecordBudget::kStep;  // budget taken, of which values_ used
  std::uint64_t values_ = 0;                  // bytes of values appended
  std::string why_cut_;
};

class Recordings {
 public:
  explicit Recordings(const ServerConfig& cfg) : budget_(cfg) {}
  ~Recordings() { wait(); }
  RecordBudget& budget() { return budget_; }
  // Puts `recording` in place off the control loop (logged; one without
  // frames is dropped, leaving nothing).
  void finish(std::unique_ptr<Recording> recording);
  // Waits for every finish under way.
  void wait();

 private:
  RecordBudget budget_;
  std::vector<std::future<void>> running_;
};

}  // namespace gmr::server
