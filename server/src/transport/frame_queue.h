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
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "gmr/wire/frame_head.h"
#include "transport/outbox.h"

namespace gmr::server {

struct PendingFrame {
  using Clock = std::chrono::steady_clock;
  std::uint32_t key = 0;
  wire::FrameHead head;                                   // this client's length prefix and ids
  std::shared_ptr<const std::string> body;                // shared by every subscriber of the stream
  Clock::time_point stale_at = Clock::time_point::max();  // not written after this
  Clock::time_point pushed_at{};
  Clock::time_point made_at{};  // its stream's fan-out began
  std::uint64_t size() const { return head.size() + body->size(); }
};

// The frames are one vector in the order they were pushed (a connection holds
// a few at a time: per_key per subscription while a write is in flight), so
// queueing and writing them allocates nothing once it has grown.
class FrameQueue {
 public:
  using Clock = std::chrono::steady_clock;

  FrameQueue(std::size_t per_key, std::size_t max_bytes)
      : per_key_(std::max<std::size_t>(1, per_key)), max_bytes_(max_bytes) {}

  // Queues `f` (for its key). `writing`: a write is in flight, behind which
  // frames wait for the client to read (the per-key and byte bounds apply).
  // Without one the frame goes out with the next write, soon (at once, or
  // when its I/O thread takes the write the control loop handed it): it is
  // kept whatever the per-key bound, within twice the byte bound.
  // `over_budget`: the server-wide buffer budget is exceeded (a frame that
  // would wait is dropped). False when a frame was dropped (counted in `c`).
  bool push(PendingFrame f, bool writing, bool over_budget, ConnectionCounters& c) {
    const std::uint64_t size = f.size();
    if (writing && over_budget) {
      ++c.frames_dropped;
      return false;
    }
    bool kept_all = true;
    if (writing && count(f.key) >= per_key_) {
      drop_oldest(f.key, c);
      kept_all = false;
    }
    if (!writing && max_bytes_ != 0 && bytes_ + size > 2 * max_bytes_) {
      // A lane that does not come round (a starved thread): bounded all the same.
      ++c.frames_dropped;
      return false;
    }
    if (writing && max_bytes_ != 0) {
      // The oldest of this key give way; a frame that would still not fit
      // beside the other keys' frames is dropped.
      while (bytes_ + size > max_bytes_ && drop_oldest(f.key, c)) kept_all = false;
      if (bytes_ != 0 && bytes_ + size > max_bytes_) {
        ++c.frames_dropped;
        return false;
      }
    }
    bytes_ += size;
    frames_.push_back(std::move(f));
    return kept_all;
  }

  std::uint64_t bytes() const { return bytes_; }
  std::size_t count() const { return frames_.size(); }
  bool empty() const { return frames_.empty(); }
  bool waiting(std::uint32_t key) const {
    return std::any_of(frames_.begin(), frames_.end(), [key](const PendingFrame& f) { return f.key == key; });
  }
  std::uint64_t stale_dropped(std::uint32_t key) const {
    auto it = stale_.find(key);
    return it == stale_.end() ? 0 : it->second;
  }
  // Forgets the frames of `key` and its stale count.
  void discard(std::uint32_t key) {
    stale_.erase(key);
    take(key);
  }
  // Removes and returns the frames of `key`, oldest first.
  std::vector<PendingFrame> take(std::uint32_t key) {
    std::vector<PendingFrame> out;
    auto kept = frames_.begin();
    for (auto& f : frames_) {
      if (f.key == key) {
        bytes_ -= f.size();
        out.push_back(std::move(f));
      } else {
        *kept++ = std::move(f);
      }
    }
    frames_.erase(kept, frames_.end());
    return out;
  }
  // Empties the queue: `write(frame)` for each frame still fresh at `now`,
  // in the order they were pushed; stale ones are counted.
  template <class Write>
  void drain(Clock::time_point now, ConnectionCounters& c, Write&& write) {
    for (auto& f : frames_) {
      if (fresh(f, now, c)) write(f);
    }
    clear();
  }
  // The oldest fresh frame of the first key at or after `cursor` that has
  // one (wrapping round), removed; `cursor` moves past its key, so keys
  // take turns. Stale frames met on the way are dropped and counted.
  std::optional<PendingFrame> pop_next(std::uint32_t& cursor, Clock::time_point now, ConnectionCounters& c) {
    while (!frames_.empty()) {
      // The smallest key at or after the cursor, else the smallest of all;
      // the first of its frames is its oldest.
      auto next = frames_.end(), first = frames_.begin();
      for (auto it = frames_.begin(); it != frames_.end(); ++it) {
        if (it->key < first->key) first = it;
        if (it->key >= cursor && (next == frames_.end() || it->key < next->key)) next = it;
      }
      if (next == frames_.end()) next = first;
      PendingFrame f = std::move(*next);
      frames_.erase(next);
      bytes_ -= f.size();
      cursor = f.key + 1;
      if (fresh(f, now, c)) return f;
    }
    return std::nullopt;
  }
  void clear() {
    frames_.clear();
    bytes_ = 0;
  }

 private:
  std::size_t count(std::uint32_t key) const {
    return static_cast<std::size_t>(
        std::count_if(frames_.begin(), frames_.end(), [key](const PendingFrame& f) { return f.key == key; }));
  }
  // Drops the oldest frame of `key` (counted); false when it has none.
  bool drop_oldest(std::uint32_t key, ConnectionCounters& c) {
    auto it = std::find_if(frames_.begin(), frames_.end(), [key](const PendingFrame& f) { return f.key == key; });
    if (it == frames_.end()) return false;
    bytes_ -= it->size();
    frames_.erase(it);
    ++c.frames_dropped;
    return true;
  }
  // False (counted) when `f` waited past its subscriber's staleness bound.
  bool fresh(const PendingFrame& f, Clock::time_point now, ConnectionCounters& c) {
    if (f.stale_at >= now) return true;
    ++c.frames_dropped;
    ++c.frames_stale;
    ++stale_[f.key];
    return false;
  }

  std::size_t per_key_;
  std::size_t max_bytes_;
  std::vector<PendingFrame> frames_;  // oldest first
  std::uint64_t bytes_ = 0;
  std::map<std::uint32_t, std::uint64_t> stale_;  // per key: frames dropped for their age
};

}  // namespace gmr::server
