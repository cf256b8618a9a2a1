// Connection: the transport of one TCP client. It reads length-prefixed
// messages and hands each body to its Handler, writes what it is given with
// one write in flight, and watches the link. It knows nothing of views,
// streams or the protocol's requests.
//
//   socket --read loop--> Handler::on_message(body)
//   send(reply) -------+
//   push_frame(key) ---+--> outbox --one async_write at a time--> socket
//                          replies in order, then frames; per key at most
//                          frames_per_key waiting (the oldest gives way)
//   watchdog: idle timeout, stuck write, heartbeat when nothing was written
//
// Bounded: replies waiting above max_reply_queue_bytes stop the read loop
// until they drain (a client that sends faster than it reads waits);
// frames are latest-wins per key. Everything runs on the I/O thread.
#pragma once

#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "net.h"

namespace gmr::server {

struct ConnectionLimits {
  std::uint32_t max_message_bytes = 0;    // a longer length prefix closes the connection
  std::size_t max_reply_queue_bytes = 0;  // above it, requests are not read until replies drain
  std::size_t frames_per_key = 1;         // frames waiting per key (subscription)
  std::chrono::milliseconds idle_timeout{0};
  std::chrono::milliseconds heartbeat_interval{0};
  std::chrono::milliseconds write_timeout{0};
  int socket_send_buffer = 0;             // SO_SNDBUF; 0: the system's default
};

struct ConnectionCounters {
  std::uint64_t frames_sent = 0;
  std::uint64_t frames_dropped = 0;    // a newer frame replaced it, or (UDP) over the datagram bound
  std::uint64_t queued_bytes = 0;      // replies and frames waiting or being written
  std::uint64_t max_queued_bytes = 0;  // high-water mark
};

class Connection : public std::enable_shared_from_this<Connection> {
 public:
  // What the connection hands its messages to.
  class Handler {
   public:
    virtual ~Handler() = default;
    // One whole message body (without its length prefix).
    virtual void on_message(const std::string& body) = 0;
    // The connection stopped (called once, before the socket closes).
    virtual void on_stop() = 0;
  };

  Connection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits);

  // Starts reading and the watchdog. `on_closed` runs once when it stopped.
  void start(std::shared_ptr<Handler> handler, std::function<void(std::uint64_t id)> on_closed);
  // Ends the connection now: the handler's on_stop, then the socket closes.
  // Idempotent.
  void stop(const std::string& reason);
  // Graceful: drop waiting frames, write the waiting replies, then stop.
  void finish();
  // The same, but the next reply (queued after this call) is written too.
  void close_after_reply();

  std::uint64_t id() const { return id_; }
  const std::string& peer() const { return peer_; }
  bool stopped() const { return stopped_; }
  // Stopped, or finishing: no more frames are taken.
  bool closing() const { return stopped_ || close_after_flush_; }

  // Queues a reply (already length-prefixed); replies go out in order.
  void send(std::string framed);
  // Queues a frame: `head` (this client's length prefix and ids) before the
  // shared `body`. False when the key already had frames_per_key waiting and
  // the oldest was dropped to make room (counted).
  bool push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body);
  // Forgets the frames waiting for `key`.
  void discard_frames(std::uint32_t key);
  // Moves the frames waiting for `key` into the reply queue, so they go out
  // before the next reply (an end notice follows its last frames).
  void send_frames_now(std::uint32_t key);
  // Frames sent or dropped elsewhere (UDP) count with this connection.
  void count_frame_sent() { ++counters_.frames_sent; }
  void count_frame_dropped() { ++counters_.frames_dropped; }

  ConnectionCounters counters() const;

 private:
  struct PendingFrame {
    std::string head;
    std::shared_ptr<const std::string> body;
  };

  net::awaitable<void> read_loop(std::shared_ptr<Connection> self);
  void flush();
  void arm_watchdog();
  std::uint64_t queued_bytes() const;
  void note_queue();

  tcp::socket socket_;
  std::uint64_t id_;
  ConnectionLimits limits_;
  std::string peer_;
  std::shared_ptr<Handler> handler_;
  std::function<void(std::uint64_t)> on_closed_;
  bool stopped_ = false;
  bool close_after_flush_ = false;

  std::deque<std::shared_ptr<const std::string>> replies_;
  std::uint64_t reply_bytes_ = 0;
  std::map<std::uint32_t, std::deque<PendingFrame>> frames_;  // per key, oldest first
  bool writing_ = false;
  std::uint64_t in_flight_bytes_ = 0;
  std::vector<std::shared_ptr<const std::string>> hold_;  // what the write in flight points into
  std::vector<std::string> hold_heads_;
  Clock::time_point write_started_{}, last_read_{}, last_write_{};
  net::steady_timer watchdog_;
  net::steady_timer read_gate_;
  ConnectionCounters counters_;
};

}  // namespace gmr::server
