// Connection: the transport of one TCP client. It reads length-prefixed
// messages and hands each body to its Handler, writes what it is given with
// one write in flight, and watches the link. It knows nothing of views,
// streams or the protocol's requests.
//
//   socket --reads--> Handler::on_message(body)
//   send(reply) -------+
//   push_frame(key) ---+--> outbox --one async_write at a time--> socket
//                          replies in order, then frames; per key at most
//                          frames_per_key waiting (the oldest gives way)
//   watchdog: idle timeout, stuck write, heartbeat when nothing was written
//
// Bounded: replies held (waiting or being written) above
// max_reply_queue_bytes stop the read loop until they drain (a client that
// sends faster than it reads waits); frames are latest-wins per key, at most
// max_frame_bytes in all; a request body grows as its bytes arrive (a length
// prefix reserves nothing). Every byte held counts in the server-wide
// BufferBudget: above its limit, connections holding more than their share
// are not read and frames that would wait are dropped. With TLS, the
// handshake comes before the first read. Everything runs on the I/O thread.
#pragma once

#include <algorithm>
#include <array>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "gmr/wire/tls_socket.h"
#include "net.h"
#include "frame_queue.h"
#include "outbox.h"

namespace prometheus {
class Histogram;
}

namespace gmr::server {

// The bytes all connections hold for their clients (replies, frames, writes
// in flight, request bodies being read), against one limit.
struct BufferBudget {
  std::uint64_t limit = 0;  // 0: none
  std::uint64_t held = 0;
  std::uint64_t max_held = 0;  // high-water mark
  // Over the limit, a connection holding more than this is not read (one
  // holding less, say a new client, still is: stuck clients cannot lock
  // everyone out).
  std::uint64_t fair_share = 0;
  bool over() const { return limit != 0 && held > limit; }
  // A connection that counted `accounted` bytes now holds `now`.
  void settle(std::uint64_t& accounted, std::uint64_t now) {
    held = held - accounted + now;
    max_held = std::max(max_held, held);
    accounted = now;
  }
  // Whether a connection holding `accounted` bytes may be read.
  bool allows_reading(std::uint64_t accounted) const { return !(over() && accounted > fair_share); }
};

struct ConnectionLimits {
  std::uint32_t max_message_bytes = 0;    // a longer length prefix closes the connection
  std::size_t max_reply_queue_bytes = 0;  // above it, requests are not read until replies drain
  std::size_t frames_per_key = 1;         // frames waiting per key (subscription)
  std::size_t max_frame_bytes = 0;        // frames waiting, all keys (0: no limit but frames_per_key)
  // While a write has been in flight this long with a key's frames waiting
  // in full, that key is congested (streams skip computing its frames).
  std::chrono::milliseconds congested_after{50};
  std::chrono::milliseconds idle_timeout{0};
  std::chrono::milliseconds handshake_timeout{0};  // 0: none
  std::chrono::milliseconds heartbeat_interval{0};
  std::chrono::milliseconds write_timeout{0};
  int socket_send_buffer = 0;             // SO_SNDBUF; 0: the system's default
  int socket_unsent_bytes = 0;            // TCP_NOTSENT_LOWAT; 0: the system's default
};

// Socket options every accepted client socket gets: no Nagle delay, the
// configured send buffer and unsent-bytes bound.
void tune_socket(tcp::socket& socket, const ConnectionLimits& limits, std::uint64_t id);

// The watchdog both transports run: its period, and why it stops a link
// (empty: it lives on).
struct LinkTimes {
  bool established = false;  // said Hello
  bool writing = false;      // a write is in flight
  Clock::time_point started, last_read, write_started, last_frames_written;
};
std::chrono::milliseconds watchdog_period(const ConnectionLimits& limits, bool established);
std::string watchdog_verdict(const LinkTimes& times, const ConnectionLimits& limits, Clock::time_point now,
                             std::uint64_t id);
// A framed Heartbeat, what the server writes when it wrote nothing for a while.
std::string heartbeat_message();

class Connection final : public CountingOutbox, public std::enable_shared_from_this<Connection> {
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

  // `budget` and `tls` (either may be null) outlive the connection. With
  // `tls` the connection speaks TLS: its handshake comes first.
  Connection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
             BufferBudget* budget = nullptr, net::ssl::context* tls = nullptr);
  ~Connection() override;

  // Starts reading and the watchdog. `on_closed` runs once when it stopped.
  void start(std::shared_ptr<Handler> handler, std::function<void(std::uint64_t id)> on_closed);
  // Ends the connection now: the handler's on_stop, then the socket closes.
  // Idempotent.
  void stop(const std::string& reason) override;
  // Graceful: drop waiting frames, write the waiting replies, then stop.
  void finish() override;

  // Outbox (outbox.h). A key holds at most frames_per_key frames; the frames
  // of send_frames_now go into the reply queue, so an end notice follows its
  // last frames.
  std::uint64_t id() const override { return id_; }
  bool stopped() const override { return stopped_; }
  bool closing() const override { return stopped_ || close_after_flush_; }
  void send(std::string framed) override;
  bool push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body,
                  Clock::duration max_age = {}) override;
  std::uint64_t stale_dropped(std::uint32_t key) const override;
  bool congested(std::uint32_t key) const override;
  void discard_frames(std::uint32_t key) override;
  void send_frames_now(std::uint32_t key) override;
  void close_after_reply() override;
  void established() override { established_ = true; }
  void hold_reading(bool hold) override;
  const std::string& peer_address() const { return peer_address_; }
  // Observes, per write that carried frames, how long its oldest frame
  // waited from push_frame to the write's completion (seconds).
  void set_frame_wait_histogram(prometheus::Histogram* h) { frame_wait_ = h; }
  ConnectionCounters counters() const override;

 private:
  // The read chain: prefix, then body, then the handler, then the next
  // prefix; it pauses while replies wait above max_reply_queue_bytes and
  // flush() resumes it.
  void read_prefix();
  void on_prefix(const boost::system::error_code& ec);
  void read_body();
  void on_body(const boost::system::error_code& ec, std::size_t got);
  void flush();
  void arm_watchdog();
  std::uint64_t queued_bytes() const { return reply_bytes_ + frames_.bytes() + in_flight_bytes_; }
  // Bytes held now (queued plus the request body being read) into the budget.
  void account();
  void note_queue();
  // Reading may go on: replies and the budget allow it.
  bool may_read() const;

  wire::TlsSocket socket_;
  std::uint64_t id_;
  ConnectionLimits limits_;
  std::string peer_;
  std::string peer_address_;  // the IP address alone
  bool established_ = false;
  Clock::time_point started_ = Clock::now();
  std::shared_ptr<Handler> handler_;
  std::function<void(std::uint64_t)> on_closed_;
  bool stopped_ = false;
  bool close_after_flush_ = false;
  bool read_paused_ = false;
  bool reads_held_ = false;  // hold_reading
  BufferBudget* budget_;
  std::uint64_t accounted_ = 0;  // what this connection added to budget_->held
  std::array<std::uint8_t, 4> prefix_{};
  std::string body_;
  std::size_t body_expected_ = 0;  // bytes the length prefix announced
  std::size_t body_received_ = 0;

  std::deque<std::shared_ptr<const std::string>> replies_;
  std::uint64_t reply_bytes_ = 0;
  FrameQueue frames_;
  bool writing_ = false;
  std::uint64_t in_flight_bytes_ = 0;
  std::vector<std::shared_ptr<const std::string>> hold_;  // what the write in flight points into
  std::vector<std::string> hold_heads_;
  std::string tls_out_;  // with TLS: the write in flight in one piece (one record per 16 KiB, not per buffer)
  bool secured_ = false;   // the TLS handshake is done (or there is no TLS): writing may start
  bool writing_frames_ = false;  // the write in flight holds frames
  Clock::time_point oldest_frame_in_flight_ = Clock::time_point::max();
  prometheus::Histogram* frame_wait_ = nullptr;
  Clock::time_point write_started_{}, last_read_{}, last_write_{};
  Clock::time_point last_frames_written_{};  // the last write that held frames completed
  net::steady_timer watchdog_;
};

}  // namespace gmr::server
