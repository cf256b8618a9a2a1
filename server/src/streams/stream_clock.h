// StreamClock: the ticks of every stream of the control loop on one timer.
//
// A stream with a timer of its own cost a timer update and a wake-up per
// tick: at 300 own UDP streams the server made 20,000 timerfd_settime calls a
// second for 36,000 datagrams (15% of its profile, epoll_wait 10% more).
// Here each stream's next tick waits in one heap by its due time; the one
// timer wakes for the earliest, and a wake-up runs every tick due within
// kGrain of it (ticks run at most kGrain early, never late for it), so the
// ticks of streams due close together share one wake-up, and their sends
// leave in one batch per I/O thread (io_threads.h hands a pass's work over
// at once).
//
// A tick scheduled while the clock runs others (a stream's next one, a new
// stream's first) waits for the next pass even when due: a stream far
// behind catches up one tick per pass, between the loop's other handlers,
// as it did with a timer of its own.
//
// Streams that start at different times would still tick at as many phases
// of their period as there are streams, and each phase's sends are a burst
// of their own (on loopback each burst wakes the receiver, which the sending
// CPU pays for). So a stream starts on a grid (ServerConfig::tick_grid): at
// rate R, one of ceil(1 / (R * grid)) points evenly spaced over its period,
// counted from the clock's epoch. Streams of one rate then tick in that many
// groups at most (5 a period at 120 Hz with the 2 ms default). The points are
// taken in turn, so streams that start together (a client that subscribes
// to a hundred at once) spread evenly over the period instead of making one
// burst: a start waits for its turn's point, less than a period, but not
// more than kLongestStartWait (past it, it takes the first point, out of
// turn, which waits less than the grid).
#pragma once

#include <cstdint>
#include <memory>
#include <algorithm>
#include <array>
#include <vector>

#include "transport/net.h"

namespace gmr::server {

class Stream;

class StreamClock {
 public:
  static constexpr Clock::duration kGrain = std::chrono::microseconds(500);
  static constexpr Clock::duration kLongestStartWait = std::chrono::milliseconds(10);

  // `grid`: see above; zero puts no grid (a stream starts when asked).
  explicit StreamClock(net::io_context& io, Clock::duration grid = Clock::duration::zero())
      : timer_(io), grid_(grid), epoch_(Clock::now()) {}

  // When a stream at `rate_hz` asked to start at `t` starts: its point of the
  // grid, the next in turn at or after `t` (`t` itself without a grid).
  Clock::time_point start_at(Clock::time_point t, double rate_hz);

  // `stream`'s tick `generation` is due at `due`: then its on_clock(generation)
  // runs (the stream ignores a generation it has since cancelled). Control
  // loop only.
  void schedule(std::weak_ptr<Stream> stream, Clock::time_point due, std::uint64_t generation);
  // No more ticks (server shutdown).
  void stop();

  // Wake-ups so far, and ticks run (for tests and benchmarks).
  std::uint64_t wakeups() const { return wakeups_; }
  std::uint64_t ticks() const { return ticks_; }
  std::size_t waiting() const { return heap_.size(); }

 private:
  struct Entry {
    Clock::time_point due;
    std::uint64_t order;  // scheduling order: ties, and what a pass may run
    std::uint64_t generation;
    std::weak_ptr<Stream> stream;
    bool operator>(const Entry& o) const { return due != o.due ? due > o.due : order > o.order; }
  };
  // The timer set for the earliest tick, unless it already is.
  void arm();
  void run_due();

  net::steady_timer timer_;
  Clock::duration grid_;
  Clock::time_point epoch_;
  // Each rate's next point in turn, by its period's hash: a fixed table, so
  // clients asking for many different rates cannot grow it (rates that share
  // a slot share a turn, which still spreads them).
  std::array<std::uint64_t, 64> turn_{};
  // A min-heap by due time (std::push_heap / pop_heap with std::greater): a
  // tick's entry is moved out of it, not copied (its weak_ptr's count is
  // shared with every other user of the stream).
  std::vector<Entry> heap_;
  std::uint64_t next_order_ = 0;
  bool waiting_ = false;  // an async_wait is pending for armed_at_
  Clock::time_point armed_at_{};
  bool stopped_ = false;
  bool in_pass_ = false;  // run_due() is running ticks
  std::uint64_t wakeups_ = 0, ticks_ = 0;
};

}  // namespace gmr::server
