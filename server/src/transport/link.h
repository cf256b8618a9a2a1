// What every client link shares, whatever its transport: the limits cfg sets
// for a connection, the bytes all connections hold against one budget, the
// socket options, and the watchdog's period and verdict.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>

#include "gmr/server/config.h"
#include "transport/net.h"

namespace gmr::server {

// The bytes all connections hold for their clients (replies, frames, writes
// in flight, request bodies being read), against one limit. Connections on
// every I/O thread settle into it: the counts are atomic.
struct BufferBudget {
  BufferBudget(std::uint64_t limit_bytes = 0, std::uint64_t fair_share_bytes = 0)
      : limit(limit_bytes), fair_share(fair_share_bytes) {}
  std::uint64_t limit = 0;  // 0: none
  // Over the limit, a connection holding more than this is not read (one
  // holding less, say a new client, still is: stuck clients cannot lock
  // everyone out).
  std::uint64_t fair_share = 0;
  std::atomic<std::uint64_t> held{0};
  std::atomic<std::uint64_t> max_held{0};  // high-water mark
  bool over() const { return limit != 0 && held.load(std::memory_order_relaxed) > limit; }
  // A connection that counted `accounted` bytes now holds `now`.
  void settle(std::uint64_t& accounted, std::uint64_t now) {
    if (now == accounted) return;  // a write taking the queued frames moves bytes, it adds none
    const std::uint64_t h = held.fetch_add(now - accounted, std::memory_order_relaxed) + (now - accounted);
    std::uint64_t m = max_held.load(std::memory_order_relaxed);
    while (h > m && !max_held.compare_exchange_weak(m, h, std::memory_order_relaxed)) {
    }
    accounted = now;
  }
  // A connection that counted `accounted` bytes is gone.
  void release(std::uint64_t accounted) { held.fetch_sub(accounted, std::memory_order_relaxed); }
  // Whether a connection holding `accounted` bytes may be read.
  bool allows_reading(std::uint64_t accounted) const { return !(over() && accounted > fair_share); }
  // Request bodies announced by their length prefix are reserved before a
  // byte of them is read, from half the limit: bytes in flight stay inside
  // it however many connections announce large messages and trickle them.
  // The reservations are apart from `held` (what is there): announcing
  // without sending holds no frame back. A connection whose own bytes stay
  // within its fair share always may (a small request is always read).
  std::atomic<std::uint64_t> reserved{0};
  bool try_reserve(std::uint64_t n, std::uint64_t accounted) {
    std::uint64_t r = reserved.load(std::memory_order_relaxed);
    do {
      if (limit != 0 && r + n > limit / 2 && accounted + n > fair_share) return false;
    } while (!reserved.compare_exchange_weak(r, r + n, std::memory_order_relaxed));
    return true;
  }
  void unreserve(std::uint64_t n) { reserved.fetch_sub(n, std::memory_order_relaxed); }
};

struct ConnectionLimits {
  std::uint32_t max_message_bytes = 0;    // a longer length prefix closes the connection
  std::size_t max_reply_queue_bytes = 0;  // above it, requests are not read until replies drain
  std::size_t frames_per_key = 1;         // frames waiting per key (subscription)
  std::size_t max_frame_bytes = 0;        // frames waiting, all keys (0: no limit but frames_per_key)
  // While a write has been in flight this long with a key's frames waiting
  // in full, or a write handed to the connection's I/O thread has waited
  // this long for it, that key is congested (streams skip computing its
  // frames, counting them dropped).
  std::chrono::milliseconds congested_after{50};
  std::chrono::milliseconds idle_timeout{0};
  std::chrono::milliseconds handshake_timeout{0};  // 0: none
  std::chrono::milliseconds heartbeat_interval{0};
  std::chrono::milliseconds write_timeout{0};
  int socket_send_buffer = 0;   // SO_SNDBUF; 0: the system's default
  int socket_unsent_bytes = 0;  // TCP_NOTSENT_LOWAT; 0: the system's default
};

// The limits cfg sets for each client connection.
ConnectionLimits connection_limits(const ServerConfig& cfg);

// Socket options every accepted client socket gets: no Nagle delay, the
// configured send buffer and unsent-bytes bound.
void tune_socket(tcp::socket& socket, const ConnectionLimits& limits, std::uint64_t id);

// The watchdog both transports run: its period, and why it stops a link
// (empty: it lives on).
struct LinkTimes {
  bool established = false;  // said Hello
  bool writing = false;      // a write is in flight
  Clock::time_point started, last_read, write_started, last_frames_written;
  bool holding = false;         // the session holds a view or a live source
  Clock::time_point last_held;  // its last request or Hello while it held nothing
};
std::chrono::milliseconds watchdog_period(const ConnectionLimits& limits, bool established);
// When a connection's next watchdog tick is due: a period from `now`,
// rounded up to a multiple of a quarter period (counted from the clock's
// epoch), so the ticks of many connections with the same limits fall due
// together: one wake-up of their I/O thread and one timer update serve them
// all, instead of one each (10,000 idle connections were 8,000 wake-ups a second).
Clock::time_point watchdog_due(const ConnectionLimits& limits, bool established, Clock::time_point now);
// When the watchdog next looks at a link that is not `polled`: at the first
// of its deadlines (a heartbeat due since `last_write`, when `ready`, unless
// overdue while a write is in flight; the idle, held, write or handshake timeout), rounded up as
// watchdog_due rounds. Deadlines only move later, but two that may begin
// after the tick is armed: a write's timeout and a session's idle timeout
// once it lets go of what it held; the tick is never further off than the
// shorter of those timeouts, so neither is missed. A `polled` link (its
// reads wait for the budget or the Handler; or it is not established or not
// ready yet, when the heartbeat's deadline is still to come) is looked at
// every period (watchdog_due). An idle multicast subscriber's connection wakes once per
// heartbeat, not four times (a period is a quarter of the shortest timeout).
Clock::time_point watchdog_next(const LinkTimes& times, Clock::time_point last_write, bool ready, bool polled,
                                const ConnectionLimits& limits, Clock::time_point now);
std::string watchdog_verdict(const LinkTimes& times, const ConnectionLimits& limits, Clock::time_point now,
                             std::uint64_t id);
// A framed Heartbeat, what the server writes when it wrote nothing for a while.
std::string heartbeat_message();

}  // namespace gmr::server
