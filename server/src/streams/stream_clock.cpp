#include "streams/stream_clock.h"

#include <cmath>

#include "streams/stream.h"

namespace gmr::server {

Clock::time_point StreamClock::start_at(Clock::time_point t, double rate_hz) {
  if (grid_ <= Clock::duration::zero() || !(rate_hz > 0) || t <= epoch_) return t;
  using Seconds = std::chrono::duration<double>;
  const double period = 1.0 / rate_hz;
  const double points_d = std::max(1.0, std::ceil(period / Seconds(grid_).count() - 1e-9));
  const auto points = static_cast<std::uint64_t>(points_d);
  const double step = period / points_d;
  // The first point at or after t (days after the epoch, n * step is still
  // within a nanosecond of the grid), then this rate's turn from there.
  auto n = static_cast<std::uint64_t>(std::ceil(Seconds(t - epoch_).count() / step));
  const auto period_ns = static_cast<std::uint64_t>(std::llround(period * 1e9));
  std::uint64_t& turn = turn_[(period_ns * 0x9E3779B97F4A7C15ull) >> 58];
  auto point = [&](std::uint64_t k) {
    return epoch_ + std::chrono::duration_cast<Clock::duration>(Seconds(static_cast<double>(k) * step));
  };
  const std::uint64_t ahead = (turn % points + points - n % points) % points;
  if (point(n + ahead) - t <= kLongestStartWait) n += ahead;
  turn = (n + 1) % points;
  return std::max(t, point(n));
}

void StreamClock::schedule(std::weak_ptr<Stream> stream, Clock::time_point due, std::uint64_t generation) {
  if (stopped_) return;
  heap_.push_back(Entry{due, next_order_++, generation, std::move(stream)});
  std::push_heap(heap_.begin(), heap_.end(), std::greater<>());
  if (!in_pass_) arm();  // a pass arms once, at its end
}

void StreamClock::stop() {
  stopped_ = true;
  heap_.clear();
  timer_.cancel();
}

void StreamClock::arm() {
  if (heap_.empty() || (waiting_ && armed_at_ <= heap_.front().due)) return;
  armed_at_ = heap_.front().due;
  waiting_ = true;
  // Setting the expiry cancels a wait already pending: its handler sees
  // operation_aborted and leaves the state to this one.
  timer_.expires_at(armed_at_);
  timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec == net::error::operation_aborted) return;
    waiting_ = false;
    run_due();
  });
}

void StreamClock::run_due() {
  if (stopped_) return;
  ++wakeups_;
  in_pass_ = true;
  const std::uint64_t pass_end = next_order_;  // ticks scheduled from here on wait for the next pass
  const Clock::time_point horizon = Clock::now() + kGrain;
  std::vector<Entry> later;  // due, but scheduled during this pass
  while (!heap_.empty() && heap_.front().due <= horizon) {
    std::pop_heap(heap_.begin(), heap_.end(), std::greater<>());
    Entry e = std::move(heap_.back());
    heap_.pop_back();
    if (e.order >= pass_end) {
      later.push_back(std::move(e));
      continue;
    }
    if (auto s = e.stream.lock()) {
      ++ticks_;
      s->on_clock(e.generation);
    }
    if (stopped_) return;
  }
  in_pass_ = false;
  for (auto& e : later) {
    heap_.push_back(std::move(e));
    std::push_heap(heap_.begin(), heap_.end(), std::greater<>());
  }
  arm();
}

}  // namespace gmr::server
