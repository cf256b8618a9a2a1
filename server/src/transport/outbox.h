// Outbox: what a client's requests and subscriptions need from its transport.
// QueuedOutbox (queued_outbox.h) implements it for Connection (TCP) and
// WsConnection (WebSocket), the ones the server runs; tests use one that only
// records, to run a RequestHandler without sockets.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "gmr/wire/frame_head.h"

namespace gmr::server {

// How long a client's frames waited in the server, from their stream's
// fan-out (the frame made, the sends begun) to their write (TCP, WebSocket)
// or their hand-over to the UDP sender: a count per power of two of
// microseconds (bucket k: under 2^k us; the last: the rest). Cheap enough to
// fill per frame, and small enough to keep per connection, so the tail is
// seen per client and not only over all frames (metrics.h).
class WaitHistogram {
 public:
  static constexpr std::size_t kBuckets = 20;  // the last from 2^18 us = 0.26 s up

  // The bucket of a wait: the first k with `waited` under 2^k us (its bit
  // width in microseconds), or the last.
  static std::size_t bucket(std::chrono::steady_clock::duration waited) {
    const auto us = std::chrono::duration_cast<std::chrono::microseconds>(waited).count();
    const auto width = us <= 0 ? 0 : std::bit_width(static_cast<std::uint64_t>(us));
    return std::min<std::size_t>(width, kBuckets - 1);
  }
  void add(std::chrono::steady_clock::duration waited) { ++counts_[bucket(waited)]; }
  // `n` more waits in bucket `k` (< kBuckets).
  void add_to_bucket(std::size_t k, std::uint64_t n) { counts_[k] += n; }
  std::uint64_t count() const {
    std::uint64_t n = 0;
    for (auto c : counts_) n += c;
    return n;
  }
  // The upper bound (seconds) of the bucket holding quantile `q` of the
  // waits (the last bucket: its lower bound); 0 with none.
  double quantile_seconds(double q) const {
    const std::uint64_t n = count();
    if (n == 0) return 0.0;
    const auto rank = static_cast<std::uint64_t>(q * static_cast<double>(n - 1));
    std::uint64_t seen = 0;
    std::size_t k = 0;
    for (; k + 1 < kBuckets; ++k) {
      seen += counts_[k];
      if (seen > rank) break;
    }
    const std::size_t bound = k + 1 < kBuckets ? k : k - 1;
    return static_cast<double>(std::int64_t{1} << bound) * 1e-6;
  }

 private:
  // 64-bit: a 1 kHz live source fills a 32-bit bucket in 50 days.
  std::array<std::uint64_t, kBuckets> counts_{};
};

struct ConnectionCounters {
  std::uint64_t frames_sent = 0;
  std::uint64_t frames_dropped = 0;      // a newer frame replaced it, or (UDP) over the datagram bound
  std::uint64_t frames_skipped = 0;      // the server was late and skipped the tick
  std::uint64_t frames_stale = 0;        // of frames_dropped: waited past their staleness bound
  std::uint64_t udp_frames_sent = 0;     // of frames_sent: over UDP
  std::uint64_t udp_frames_dropped = 0;  // of frames_dropped: over UDP
  std::uint64_t bytes_sent = 0;          // written to the connection's socket
  std::uint64_t bytes_received = 0;      // read from it
  std::uint64_t queued_bytes = 0;        // replies and frames waiting or being written
  std::uint64_t max_queued_bytes = 0;    // high-water mark
  WaitHistogram frame_wait;              // of frames_sent (not multicast), this connection's own

  // Adds another connection's totals (the gauges, queued bytes, stay).
  void add_totals(const ConnectionCounters& k) {
    frames_sent += k.frames_sent;
    frames_dropped += k.frames_dropped;
    frames_skipped += k.frames_skipped;
    frames_stale += k.frames_stale;
    udp_frames_sent += k.udp_frames_sent;
    udp_frames_dropped += k.udp_frames_dropped;
    bytes_sent += k.bytes_sent;
    bytes_received += k.bytes_received;
  }
};

class Outbox {
 public:
  virtual ~Outbox() = default;

  virtual std::uint64_t id() const = 0;
  // "tcp" or "websocket": what metrics label its counts with.
  virtual const char* transport() const { return "tcp"; }
  // The I/O thread its socket work runs on (io_threads.h); 0: the control loop.
  virtual std::size_t lane() const { return 0; }
  // Stopped: nothing more goes out.
  virtual bool stopped() const = 0;
  // Stopped, or finishing: no more frames are taken.
  virtual bool closing() const = 0;
  // Queues a reply (already length-prefixed); replies go out in order.
  virtual void send(std::string framed) = 0;
  // Queues a frame: `head` (this client's length prefix, ids and write
  // stamp, which the outbox sets as it writes the frame) before the shared
  // `body`, made (its stream's fan-out began) at `made`. False when the key
  // already had its share of frames waiting and the oldest was dropped to
  // make room (counted). A frame still waiting `max_age` after this call is
  // dropped instead of written (counted, and in end_frames(key)'s answer);
  // zero: no limit.
  virtual bool push_frame(std::uint32_t key, const wire::FrameHead& head, std::shared_ptr<const std::string> body,
                          std::chrono::steady_clock::duration max_age, std::chrono::steady_clock::time_point made) = 0;
  // True while frames for `key` cannot go out soon: its share of frames is
  // waiting behind a write that has been in flight for a while (the client
  // is not reading). Streams then skip computing frames for it.
  virtual bool congested(std::uint32_t key) const { return (void)key, false; }
  // Forgets the frames waiting for `key` (and its count of stale frames).
  virtual void discard_frames(std::uint32_t key) = 0;
  // Moves the frames waiting for `key` ahead of the next reply.
  virtual void send_frames_now(std::uint32_t key) = 0;
  // Subscription `key` ends: its waiting frames go ahead of the next reply,
  // and the key is forgotten. Returns how many of its frames were dropped
  // for waiting past their max_age, counted in the same step (a write
  // meanwhile cannot drop one the answer misses).
  virtual std::uint64_t end_frames(std::uint32_t key) = 0;
  // The client completed its handshake (the handshake deadline no longer applies).
  virtual void established() {}
  // After each request: whether the session holds anything (a view, and so
  // maybe subscriptions, or a live source). A connection that holds nothing
  // and makes no request for the idle timeout is closed however often it
  // sends heartbeats.
  virtual void set_holding(bool holding) { (void)holding; }
  // While held, no more requests are read (those sent wait in the kernel);
  // releasing resumes reading. For a request answered from another thread.
  virtual void hold_reading(bool hold) { (void)hold; }
  // Closes once the next reply (queued after this call) is out.
  virtual void close_after_reply() = 0;
  // Ends the connection now (idempotent), or gracefully: waiting frames are
  // dropped, waiting replies written, then it stops.
  virtual void stop(const std::string& reason) = 0;
  virtual void finish() = 0;
  // Frames sent (having waited `waited` since their fan-out began) or dropped
  // elsewhere (UDP), and frames a stream dropped or skipped for this client,
  // count with it.
  virtual void count_udp_frame_sent(std::chrono::steady_clock::duration waited) = 0;
  virtual void count_udp_frame_dropped() = 0;
  virtual void count_frame_dropped(std::uint64_t n) = 0;
  virtual void count_frame_skipped(std::uint64_t n) = 0;
  virtual ConnectionCounters counters() const = 0;
};

}  // namespace gmr::server
