#include "live/recordings.h"

#include <spdlog/spdlog.h>
#include <sys/statvfs.h>

#include <chrono>
#include <filesystem>
#include <system_error>

namespace gmr::server {

namespace {

// Bytes of the regular files directly in `dir` (temporaries of recordings
// under way included: they are counted as held until they finish).
std::uint64_t directory_bytes(const std::string& dir) {
  std::uint64_t total = 0;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.starts_with(".") && name.find(".tmp.") != std::string::npos) continue;
    std::error_code size_ec;
    if (it->is_regular_file(size_ec)) {
      const auto size = it->file_size(size_ec);
      if (!size_ec) total += size;
    }
  }
  return total;
}

std::uint64_t free_bytes(const std::string& dir) {
  struct statvfs s {};
  if (::statvfs(dir.c_str(), &s) != 0) return ~std::uint64_t{0};  // unknown: the other bounds hold
  return static_cast<std::uint64_t>(s.f_bavail) * s.f_frsize;
}

std::string mib(std::uint64_t bytes) { return std::to_string((bytes + (1u << 19)) >> 20) + " MiB"; }

}  // namespace

std::string RecordBudget::bound_passed(std::uint64_t more) const {
  if (held_ + more > cfg_.max_record_total_bytes) {
    return "recordings under way hold " + mib(held_) + " of --max-record-total-bytes " +
           mib(cfg_.max_record_total_bytes);
  }
  if (cfg_.max_record_dir_bytes > 0 && dir_bytes_ + held_ + more > cfg_.max_record_dir_bytes) {
    return "the record directory holds " + mib(dir_bytes_) + " and recordings under way " + mib(held_) +
           " of --max-record-dir-bytes " + mib(cfg_.max_record_dir_bytes);
  }
  if (free_bytes(cfg_.record_dir) < more + kFreeReserve) {
    return "the disk of the record directory has less than " + mib(more + kFreeReserve) + " free";
  }
  return {};
}

std::string RecordBudget::admit() {
  std::lock_guard lock(m_);
  dir_bytes_ = directory_bytes(cfg_.record_dir);
  std::string why = bound_passed(kStep);
  if (why.empty()) {
    held_ += kStep;
  } else {
    ++refused_;
  }
  return why;
}

bool RecordBudget::take(std::uint64_t bytes) {
  std::lock_guard lock(m_);
  if (!bound_passed(bytes).empty()) return false;
  held_ += bytes;
  return true;
}

void RecordBudget::release(std::uint64_t held, std::uint64_t file_bytes) {
  std::lock_guard lock(m_);
  held_ -= held;
  dir_bytes_ += file_bytes;
}

std::uint64_t RecordBudget::held() const {
  std::lock_guard lock(m_);
  return held_;
}

std::uint64_t RecordBudget::refused() const {
  std::lock_guard lock(m_);
  return refused_;
}

Recording::Recording(GmrbAppender file, std::uint64_t max_bytes, RecordBudget& budget, std::string name)
    : file_(std::move(file)), max_bytes_(max_bytes), budget_(budget), name_(std::move(name)) {}

Recording::~Recording() {
  // Not finished (the server stopped, or nothing was recorded): the
  // appender removes its temporary.
  if (held_ > 0) budget_.release(held_, 0);
}

void Recording::stop(std::string why) {
  why_cut_ = std::move(why);
  budget_.count_cut();
  spdlog::warn("live {}: the recording stops at frame {}: {}", printable(name_, 200), frames(), why_cut_);
}

void Recording::add(std::span<const double> values) {
  if (cut() || !file_) return;
  const std::uint64_t bytes = values.size() * sizeof(double);
  if (values_ + bytes > max_bytes_) {
    return stop(std::to_string(max_bytes_) + " bytes of values is the limit (--max-record-bytes)");
  }
  if (values_ + bytes > held_) {
    const std::uint64_t step = std::max(RecordBudget::kStep, bytes);
    if (!budget_.take(step)) {
      return stop("the record budget is spent (--max-record-total-bytes, --max-record-dir-bytes, free disk)");
    }
    held_ += step;
  }
  if (Status s = file_->append(values); !s.ok()) return stop(s.error().to_string());
  values_ += bytes;
}

void Recordings::finish(std::unique_ptr<Recording> recording) {
  std::erase_if(running_,
                [](std::future<void>& f) { return f.wait_for(std::chrono::seconds(0)) == std::future_status::ready; });
  if (!recording || !recording->file_ || recording->frames() == 0) {
    if (recording) spdlog::info("live {}: nothing recorded (no frames)", printable(recording->name_, 200));
    return;  // ~Recording removes the temporary and gives the budget back
  }
  running_.push_back(std::async(std::launch::async, [r = std::move(recording)]() mutable {
    const std::string file = r->file_->path().string();
    auto size = r->file_->finish();
    const std::uint64_t held = std::exchange(r->held_, 0);
    if (!size.ok()) {
      r->budget_.release(held, 0);
      spdlog::error("live {}: recording not written: {}", printable(r->name_, 200), size.error().to_string());
      return;
    }
    r->budget_.release(held, *size);
    spdlog::info("live {}: recorded {} frames to {}{}", printable(r->name_, 200), r->frames(), file,
                 r->cut() ? " (cut: " + r->why_cut() + ")" : "");
  }));
}

void Recordings::wait() {
  for (auto& r : running_) r.wait();
  running_.clear();
}

}  // namespace gmr::server
