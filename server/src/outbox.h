// Outbox: what a client's requests and subscriptions need from its transport.
// Connection (TCP) is the one the server runs; a WebSocket session would be
// another, and tests use one that only records, to run a RequestHandler
// without sockets.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

namespace gmr::server {

struct ConnectionCounters {
  std::uint64_t frames_sent = 0;
  std::uint64_t frames_dropped = 0;    // a newer frame replaced it, or (UDP) over the datagram bound
  std::uint64_t frames_skipped = 0;    // the server was late and skipped the tick
  std::uint64_t queued_bytes = 0;      // replies and frames waiting or being written
  std::uint64_t max_queued_bytes = 0;  // high-water mark
};

class Outbox {
 public:
  virtual ~Outbox() = default;

  virtual std::uint64_t id() const = 0;
  // Stopped: nothing more goes out.
  virtual bool stopped() const = 0;
  // Stopped, or finishing: no more frames are taken.
  virtual bool closing() const = 0;
  // Queues a reply (already length-prefixed); replies go out in order.
  virtual void send(std::string framed) = 0;
  // Queues a frame: `head` (this client's length prefix and ids) before the
  // shared `body`. False when the key already had its share of frames
  // waiting and the oldest was dropped to make room (counted). A frame still
  // waiting `max_age` after this call is dropped instead of written (counted,
  // and in stale_dropped(key)); zero: no limit.
  virtual bool push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body,
                          std::chrono::steady_clock::duration max_age = {}) = 0;
  // Frames of `key` dropped for waiting past their max_age.
  virtual std::uint64_t stale_dropped(std::uint32_t key) const { return (void)key, 0; }
  // True while frames for `key` cannot go out soon: its share of frames is
  // waiting behind a write that has been in flight for a while (the client
  // is not reading). Streams then skip computing frames for it.
  virtual bool congested(std::uint32_t key) const { return (void)key, false; }
  // Forgets the frames waiting for `key` (and its stale_dropped count).
  virtual void discard_frames(std::uint32_t key) = 0;
  // Moves the frames waiting for `key` ahead of the next reply.
  virtual void send_frames_now(std::uint32_t key) = 0;
  // The client completed its handshake (the handshake deadline no longer applies).
  virtual void established() {}
  // Closes once the next reply (queued after this call) is out.
  virtual void close_after_reply() = 0;
  // Frames sent or dropped elsewhere (UDP) count with this client.
  virtual void count_frame_sent() = 0;
  virtual void count_frame_dropped(std::uint64_t n = 1) = 0;
  virtual void count_frame_skipped(std::uint64_t n) = 0;
  virtual ConnectionCounters counters() const = 0;
};

}  // namespace gmr::server
