// FrameQueue: the frames a connection holds for its subscriptions while a
// write is in flight, and the slow-client policy both transports (TCP and
// WebSocket) apply to them: per key (subscription) at most `per_key` frames,
// the oldest giving way (latest wins); at most `max_bytes` in all; a frame
// still waiting past its staleness bound is dropped instead of written.
// Every frame given up is counted in the connection's counters.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "transport/outbox.h"

namespace gmr::server {

struct PendingFrame {
  using Clock = std::chrono::steady_clock;
  std::string head;                                       // this client's length prefix and ids
  std::shared_ptr<const std::string> body;                // shared by every subscriber of the stream
  Clock::time_point stale_at = Clock::time_point::max();  // not written after this
  Clock::time_point pushed_at{};
  std::uint64_t size() const { return head.size() + body->size(); }
};

class FrameQueue {
 public:
  using Clock = std::chrono::steady_clock;

  FrameQueue(std::size_t per_key, std::size_t max_bytes)
      : per_key_(std::max<std::size_t>(1, per_key)), max_bytes_(max_bytes) {}

  // Queues `f` for `key`. `writing`: a write is in flight, behind which
  // frames wait for the client to read (the per-key and byte bounds apply).
  // Without one the frame goes out with the next write, soon (at once, or
  // when its I/O thread takes the write the control loop handed it): it is
  // kept whatever the per-key bound, within twice the byte bound.
  // `over_budget`: the server-wide buffer budget is exceeded (a frame that
  // would wait is dropped). False when a frame was dropped (counted in `c`).
  bool push(std::uint32_t key, PendingFrame f, bool writing, bool over_budget, ConnectionCounters& c) {
    const std::uint64_t size = f.size();
    if (writing && over_budget) {
      ++c.frames_dropped;
      return false;
    }
    bool kept_all = true;
    auto& queue = frames_[key];
    if (writing && queue.size() >= per_key_) {
      pop_front(queue, c);
      kept_all = false;
    }
    if (!writing && max_bytes_ != 0 && bytes_ + size > 2 * max_bytes_) {
      // A lane that does not come round (a starved thread): bounded all the same.
      if (queue.empty()) frames_.erase(key);
      ++c.frames_dropped;
      return false;
    }
    if (writing && max_bytes_ != 0) {
      // The oldest of this key give way; a frame that would still not fit
      // beside the other keys' frames is dropped.
      while (!queue.empty() && bytes_ + size > max_bytes_) {
        pop_front(queue, c);
        kept_all = false;
      }
      if (bytes_ != 0 && bytes_ + size > max_bytes_) {
        if (queue.empty()) frames_.erase(key);
        ++c.frames_dropped;
        return false;
      }
    }
    bytes_ += size;
    queue.push_back(std::move(f));
    return kept_all;
  }

  std::uint64_t bytes() const { return bytes_; }
  std::size_t count() const {
    std::size_t n = 0;
    for (const auto& [key, queue] : frames_) n += queue.size();
    return n;
  }
  bool empty() const { return frames_.empty(); }
  bool waiting(std::uint32_t key) const {
    auto it = frames_.find(key);
    return it != frames_.end() && !it->second.empty();
  }
  std::uint64_t stale_dropped(std::uint32_t key) const {
    auto it = stale_.find(key);
    return it == stale_.end() ? 0 : it->second;
  }
  // Forgets the frames of `key` and its stale count.
  void discard(std::uint32_t key) {
    stale_.erase(key);
    if (auto it = frames_.find(key); it != frames_.end()) {
      for (const auto& f : it->second) bytes_ -= f.size();
      frames_.erase(it);
    }
  }
  // Removes and returns the frames of `key`, oldest first.
  std::deque<PendingFrame> take(std::uint32_t key) {
    std::deque<PendingFrame> out;
    if (auto it = frames_.find(key); it != frames_.end()) {
      out = std::move(it->second);
      for (const auto& f : out) bytes_ -= f.size();
      frames_.erase(it);
    }
    return out;
  }
  // Empties the queue: `write(key, frame)` for each frame still fresh at
  // `now`, in key order, oldest first; stale ones are counted.
  template <class Write>
  void drain(Clock::time_point now, ConnectionCounters& c, Write&& write) {
    for (auto& [key, queue] : frames_) {
      for (auto& f : queue) {
        if (!fresh(key, f, now, c)) continue;
        write(key, f);
      }
    }
    clear();
  }
  // The oldest fresh frame of the first key at or after `cursor` that has
  // one (wrapping round), removed; `cursor` moves past its key, so keys
  // take turns. Stale frames met on the way are dropped and counted.
  std::optional<PendingFrame> pop_next(std::uint32_t& cursor, Clock::time_point now, ConnectionCounters& c) {
    while (!frames_.empty()) {
      auto it = frames_.lower_bound(cursor);
      if (it == frames_.end()) it = frames_.begin();
      auto& queue = it->second;
      PendingFrame f = std::move(queue.front());
      queue.pop_front();
      bytes_ -= f.size();
      const std::uint32_t key = it->first;
      if (queue.empty()) frames_.erase(it);
      cursor = key + 1;
      if (fresh(key, f, now, c)) return f;
    }
    return std::nullopt;
  }
  void clear() {
    frames_.clear();
    bytes_ = 0;
  }

 private:
  void pop_front(std::deque<PendingFrame>& queue, ConnectionCounters& c) {
    bytes_ -= queue.front().size();
    queue.pop_front();
    ++c.frames_dropped;
  }
  // False (counted) when `f` waited past its subscriber's staleness bound.
  bool fresh(std::uint32_t key, const PendingFrame& f, Clock::time_point now, ConnectionCounters& c) {
    if (f.stale_at >= now) return true;
    ++c.frames_dropped;
    ++c.frames_stale;
    ++stale_[key];
    return false;
  }

  std::size_t per_key_;
  std::size_t max_bytes_;
  std::map<std::uint32_t, std::deque<PendingFrame>> frames_;  // per key, oldest first
  std::uint64_t bytes_ = 0;
  std::map<std::uint32_t, std::uint64_t> stale_;  // per key: frames dropped for their age
};

}  // namespace gmr::server
