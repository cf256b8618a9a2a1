// QueuedOutbox: the outbox every client transport shares (Connection over
// TCP, WsConnection over WebSocket): replies in order; frames in a FrameQueue
// (latest wins per subscription, a byte bound, the staleness bound); every
// byte held counted in the server-wide BufferBudget; the counters; the
// congestion rule; the watchdog's tick. A transport adds only its socket
// I/O: how a write goes out (request_flush), how reading resumes (read_more),
// and how it stops.
//
// Threads: every call but the UDP counts (atomic) takes m_, recursive (a
// stop may come from inside a locked step, a write that failed). Calls may
// come from the control loop (requests, streams) and from the transport's
// I/O thread; a transport whose calls all come from one thread (WebSocket)
// takes an uncontended lock.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>

#include "transport/frame_queue.h"
#include "transport/link.h"
#include "transport/outbox.h"

namespace gmr::server {

// A bool that another thread may read without the owner's lock: its loads
// and stores are relaxed atomics, so what one sees is a recent value (for a
// hint, not a decision that needs the lock's order).
class RelaxedFlag {
 public:
  RelaxedFlag& operator=(bool v) {
    v_.store(v, std::memory_order_relaxed);
    return *this;
  }
  operator bool() const { return v_.load(std::memory_order_relaxed); }

 private:
  std::atomic<bool> v_{false};
};

class LatencyHistogram;

class QueuedOutbox : public Outbox {
 public:
  // `budget` (may be null) outlives the outbox.
  QueuedOutbox(std::uint64_t id, const ConnectionLimits& limits, BufferBudget* budget);
  ~QueuedOutbox() override;

  // Outbox (outbox.h). A key holds at most limits.frames_per_key frames; the
  // frames of send_frames_now go into the reply queue, so an end notice
  // follows its last frames.
  std::uint64_t id() const override { return id_; }
  bool stopped() const override { return stopped_.load(std::memory_order_acquire); }
  bool closing() const override;
  void send(std::string framed) override;
  bool push_frame(std::uint32_t key, const wire::FrameHead& head, std::shared_ptr<const std::string> body,
                  Clock::duration max_age, Clock::time_point made) override;
  bool congested(std::uint32_t key) const override;
  void discard_frames(std::uint32_t key) override;
  void send_frames_now(std::uint32_t key) override;
  std::uint64_t end_frames(std::uint32_t key) override;
  void close_after_reply() override;
  void established() override;
  void set_holding(bool holding) override;
  void hold_reading(bool hold) override;
  void count_udp_frame_sent(Clock::duration waited) override;
  void count_udp_frame_dropped() override;
  void count_frame_dropped(std::uint64_t n) override;
  void count_frame_skipped(std::uint64_t n) override;
  ConnectionCounters counters() const override;

  // Observes, per write that carried frames, how long its oldest frame
  // waited from push_frame to the write's completion (seconds).
  void set_frame_wait_histogram(LatencyHistogram* h) { frame_wait_ = h; }

 protected:
  using Lock = std::lock_guard<std::recursive_mutex>;

  // The transport's part, each called with m_ held.
  // Replies or frames are waiting: write them (now, or once the link can).
  virtual void request_flush() = 0;
  // Reading, paused, may go on.
  virtual void read_more() = 0;
  // Bytes of a request still being read, held with the queues.
  virtual std::uint64_t reading_bytes() const { return 0; }
  // Frames wait rather than go out with the next write: a write is in
  // flight (or the link is not open yet).
  virtual bool frames_wait() const { return writing_; }
  // The link can carry a heartbeat (TLS handshake, WebSocket upgrade done).
  virtual bool link_ready() const { return true; }

  std::uint64_t queued_bytes() const { return reply_bytes_ + frames_.bytes() + in_flight_bytes_; }
  // Frames sent and dropped, over TCP (or WebSocket) and UDP (m_ held).
  std::uint64_t all_frames_sent() const { return counters_.frames_sent + udp_frames_sent(); }
  std::uint64_t all_frames_dropped() const {
    return counters_.frames_dropped + udp_dropped_.load(std::memory_order_relaxed);
  }
  // Bytes held now (queued plus the request being read) into the budget.
  void account();
  void note_queue();
  // Reading may go on: replies, the budget and the request at the handler allow it.
  bool may_read() const;
  // Calls read_more() when reading was paused and may go on now.
  void resume_reading();
  // Reading pauses. `for_budget`: the server-wide buffer budget is why (or
  // may_read found it so): nothing tells the link when it frees, so the
  // watchdog's tick, if further off, is brought within a period.
  void pause_reading(bool for_budget = false);
  // (Re)arms the transport's watchdog timer for watchdog_next_tick.
  virtual void arm_watchdog() = 0;
  // Forgets what waits (the link stops).
  void drop_queued();
  // Frame `f` (of a subscription whose frames go out now) as bytes with this
  // write's stamp, counted as sent (and its wait, to `write_time`).
  std::string stamped(PendingFrame& f, std::int64_t write_time_ns, Clock::time_point write_time);
  // One tick of the watchdog at `now`: why the link must stop (empty: it
  // lives on); meanwhile reading the budget paused resumes, and a heartbeat
  // is queued when nothing was written for a while.
  std::string watchdog_tick(Clock::time_point now);
  // When the watchdog's next tick is due (watchdog_next in link.h).
  Clock::time_point watchdog_next_tick(Clock::time_point now);
  LinkTimes link_times() const;
  // A write of `n` bytes completed (`writing_frames_`: it carried frames).
  void wrote(std::size_t n);

  mutable std::recursive_mutex m_;
  const std::uint64_t id_;
  const ConnectionLimits limits_;
  BufferBudget* const budget_;
  std::uint64_t accounted_ = 0;  // what this outbox added to budget_->held
  // Atomic: stopped() is read on every tick by each subscription's stream,
  // without the lock; set only under it.
  std::atomic<bool> stopped_{false};
  bool close_after_flush_ = false;
  bool close_on_next_reply_ = false;  // close_after_reply: the next send() closes after it
  bool established_ = false;
  bool holding_ = false;
  Clock::time_point last_held_{};
  bool read_paused_ = false;
  bool reads_held_ = false;  // hold_reading
  bool at_handler_ = false;  // a request body is with the Handler (reading waits)
  // congested() reads both without the lock first (relaxed atomics: plain
  // loads and stores on x86, so the write path pays nothing).
  RelaxedFlag writing_;
  bool writing_frames_ = false;  // the write in flight holds frames
  RelaxedFlag flush_posted_;     // a write was handed to the I/O thread, not taken yet
  Clock::time_point flush_asked_{};

  std::deque<std::shared_ptr<const std::string>> replies_;  // framed
  std::uint64_t reply_bytes_ = 0;
  FrameQueue frames_;
  std::uint64_t in_flight_bytes_ = 0;
  ConnectionCounters counters_;
  // UDP frames, counted by the streams for each UDP subscriber of every tick:
  // without the lock, folded into counters(). Those sent are counted by their
  // wait's bucket alone (their number is the buckets' sum).
  std::array<std::atomic<std::uint64_t>, WaitHistogram::kBuckets> udp_wait_{};
  std::atomic<std::uint64_t> udp_dropped_{0};
  std::uint64_t udp_frames_sent() const;

  Clock::time_point started_ = Clock::now();
  Clock::time_point tick_due_ = Clock::time_point::max();  // what watchdog_next_tick last gave
  Clock::time_point write_started_{}, last_read_{}, last_write_{};
  Clock::time_point last_frames_written_{};  // the last write that held frames completed
  Clock::time_point oldest_frame_in_flight_ = Clock::time_point::max();
  LatencyHistogram* frame_wait_ = nullptr;
};

}  // namespace gmr::server
