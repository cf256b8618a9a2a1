#include "transport/queued_outbox.h"

#include <algorithm>
#include <utility>

#include "gmr/wire/frames.h"
#include "transport/latency_histogram.h"

namespace gmr::server {

QueuedOutbox::QueuedOutbox(std::uint64_t id, const ConnectionLimits& limits, BufferBudget* budget)
    : id_(id), limits_(limits), budget_(budget), frames_(limits.frames_per_key, limits.max_frame_bytes) {}

QueuedOutbox::~QueuedOutbox() {
  if (budget_ != nullptr) budget_->release(accounted_);
}

void QueuedOutbox::account() {
  if (budget_ != nullptr) budget_->settle(accounted_, queued_bytes() + reading_bytes());
}

void QueuedOutbox::note_queue() { counters_.max_queued_bytes = std::max(counters_.max_queued_bytes, queued_bytes()); }

bool QueuedOutbox::closing() const {
  Lock lock(m_);
  return stopped_ || close_after_flush_;
}

void QueuedOutbox::established() {
  Lock lock(m_);
  established_ = true;
  last_held_ = Clock::now();
}

void QueuedOutbox::set_holding(bool holding) {
  Lock lock(m_);
  // Called after each request: a request is activity, a heartbeat is not.
  if (!holding) last_held_ = Clock::now();
  holding_ = holding;
}

void QueuedOutbox::hold_reading(bool hold) {
  Lock lock(m_);
  reads_held_ = hold;
  if (!hold) resume_reading();
}

bool QueuedOutbox::may_read() const {
  return !reads_held_ && !at_handler_ && reply_bytes_ + in_flight_bytes_ <= limits_.max_reply_queue_bytes &&
         (budget_ == nullptr || budget_->allows_reading(accounted_));
}

void QueuedOutbox::resume_reading() {
  if (stopped_ || !read_paused_ || !may_read()) return;
  read_paused_ = false;
  read_more();
}

void QueuedOutbox::pause_reading(bool for_budget) {
  read_paused_ = true;
  const bool budget =
      for_budget || (budget_ != nullptr && !reads_held_ && !at_handler_ && !budget_->allows_reading(accounted_));
  if (budget && tick_due_ > watchdog_due(limits_, established_, Clock::now())) arm_watchdog();
}

void QueuedOutbox::drop_queued() {
  frames_.clear();
  replies_.clear();
  reply_bytes_ = 0;
  account();
}

void QueuedOutbox::close_after_reply() {
  Lock lock(m_);
  close_on_next_reply_ = true;
  frames_.clear();
  account();
}

void QueuedOutbox::send(std::string framed) {
  Lock lock(m_);
  if (stopped_) return;
  reply_bytes_ += framed.size();
  replies_.push_back(std::make_shared<const std::string>(std::move(framed)));
  // Closing waits for this reply (and not for one another thread queues).
  if (std::exchange(close_on_next_reply_, false)) {
    close_after_flush_ = true;
    frames_.clear();
  }
  note_queue();
  account();
  request_flush();
}

bool QueuedOutbox::push_frame(std::uint32_t key, const wire::FrameHead& head, std::shared_ptr<const std::string> body,
                              Clock::duration max_age, Clock::time_point made) {
  Lock lock(m_);
  if (stopped_ || close_after_flush_) return true;
  // With no write in flight the frame goes out at once; otherwise it waits,
  // within this connection's bounds and the server's budget.
  const Clock::time_point now = Clock::now();
  const Clock::time_point stale_at = max_age > Clock::duration::zero() ? now + max_age : Clock::time_point::max();
  const bool kept_all = frames_.push(PendingFrame{key, head, std::move(body), stale_at, now, made}, frames_wait(),
                                     budget_ != nullptr && budget_->over(), counters_);
  note_queue();
  // Into the budget after the flush: a frame written at once (the usual
  // case) leaves the count where it was, so the budget's shared counter is
  // not touched twice a frame by every I/O thread.
  request_flush();
  account();
  return kept_all;
}

bool QueuedOutbox::congested(std::uint32_t key) const {
  // Without the lock first: a connection with no write in flight and none
  // handed to its I/O thread is not congested, which is nearly every
  // subscriber at nearly every tick (a lock pair a frame saved).
  if (!writing_ && !flush_posted_) return false;
  Lock lock(m_);
  if (stopped_) return false;
  if (!writing_) {
    // Its I/O thread has not come round to the write it was handed: the
    // thread is behind (overloaded), and frames would only pile up.
    return flush_posted_ && frames_.waiting(key) && Clock::now() - flush_asked_ > limits_.congested_after;
  }
  if (budget_ != nullptr && budget_->over()) return true;
  if (!frames_.waiting(key)) return false;
  return Clock::now() - write_started_ > limits_.congested_after;
}

void QueuedOutbox::discard_frames(std::uint32_t key) {
  Lock lock(m_);
  frames_.discard(key);
  account();
}

std::string QueuedOutbox::stamped(PendingFrame& f, std::int64_t write_time_ns, Clock::time_point write_time) {
  f.head.set_write_stamp(write_time_ns);
  std::string framed;
  framed.reserve(f.size());
  framed.append(f.head.view());
  framed += *f.body;
  ++counters_.frames_sent;
  counters_.frame_wait.add(write_time - f.made_at);
  return framed;
}

void QueuedOutbox::send_frames_now(std::uint32_t key) {
  Lock lock(m_);
  const std::int64_t now = now_ns();
  const Clock::time_point write_time = Clock::now();
  for (auto& frame : frames_.take(key)) {
    auto bytes = std::make_shared<const std::string>(stamped(frame, now, write_time));
    reply_bytes_ += bytes->size();
    replies_.push_back(std::move(bytes));
  }
  account();
}

std::uint64_t QueuedOutbox::end_frames(std::uint32_t key) {
  Lock lock(m_);
  const std::uint64_t stale = frames_.stale_dropped(key);
  send_frames_now(key);
  frames_.discard(key);
  account();
  return stale;
}

void QueuedOutbox::count_udp_frame_sent(Clock::duration waited) {
  udp_wait_[WaitHistogram::bucket(waited)].fetch_add(1, std::memory_order_relaxed);
}

std::uint64_t QueuedOutbox::udp_frames_sent() const {
  std::uint64_t n = 0;
  for (const auto& k : udp_wait_) n += k.load(std::memory_order_relaxed);
  return n;
}

void QueuedOutbox::count_udp_frame_dropped() { udp_dropped_.fetch_add(1, std::memory_order_relaxed); }

void QueuedOutbox::count_frame_dropped(std::uint64_t n) {
  Lock lock(m_);
  counters_.frames_dropped += n;
}

void QueuedOutbox::count_frame_skipped(std::uint64_t n) {
  Lock lock(m_);
  counters_.frames_skipped += n;
}

ConnectionCounters QueuedOutbox::counters() const {
  Lock lock(m_);
  ConnectionCounters c = counters_;
  c.queued_bytes = queued_bytes();
  for (std::size_t k = 0; k < WaitHistogram::kBuckets; ++k) {
    const std::uint64_t n = udp_wait_[k].load(std::memory_order_relaxed);
    c.frame_wait.add_to_bucket(k, n);
    c.udp_frames_sent += n;
  }
  c.udp_frames_dropped = udp_dropped_.load(std::memory_order_relaxed);
  c.frames_sent += c.udp_frames_sent;
  c.frames_dropped += c.udp_frames_dropped;
  return c;
}

LinkTimes QueuedOutbox::link_times() const {
  return LinkTimes{established_,         writing_, started_,  last_read_, write_started_,
                   last_frames_written_, holding_, last_held_};
}

Clock::time_point QueuedOutbox::watchdog_next_tick(Clock::time_point now) {
  // Reads waiting for the budget resume at a tick; those waiting for the
  // Handler count as reading there. Before Hello, or while the link is not
  // ready (TLS, WebSocket handshakes), deadlines come nearer as it opens.
  const bool polled = read_paused_ || reads_held_ || at_handler_ || !established_ || !link_ready();
  tick_due_ = watchdog_next(link_times(), last_write_, link_ready(), polled, limits_, now);
  return tick_due_;
}

std::string QueuedOutbox::watchdog_tick(Clock::time_point now) {
  // A client whose request the server is still on (its reads held for an
  // edit, or a body with the handler) waits for the server: not idle.
  if (reads_held_ || at_handler_) last_read_ = now;
  if (std::string why = watchdog_verdict(link_times(), limits_, now, id_); !why.empty()) return why;
  // Reads paused for the server-wide budget resume once it allows.
  resume_reading();
  if (link_ready() && !writing_ && now - last_write_ > limits_.heartbeat_interval) {
    send(heartbeat_message());
    last_write_ = now;
  }
  return {};
}

void QueuedOutbox::wrote(std::size_t n) {
  counters_.bytes_sent += n;
  last_write_ = Clock::now();
  if (!writing_frames_) return;
  last_frames_written_ = last_write_;
  if (frame_wait_ != nullptr) {
    frame_wait_->observe(last_write_ - oldest_frame_in_flight_);
  }
  oldest_frame_in_flight_ = Clock::time_point::max();
}

}  // namespace gmr::server
