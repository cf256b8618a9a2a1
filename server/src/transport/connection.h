// Connection: the transport of one TCP client. It reads length-prefixed
// messages and hands each body to its Handler, writes what it is given with
// one write in flight, and watches the link. It knows nothing of views,
// streams or the protocol's requests.
//
//   socket --reads--> Handler::on_message(body)       (on the control loop)
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
// handshake comes before the first read.
//
// Threads (io_threads.h): the socket, its reads and writes and the watchdog
// belong to the connection's lane (the io_context it was made with); the
// Handler runs on the control loop, and so do the streams that push frames.
// Every Outbox call may come from either thread: the state is under one
// mutex, and socket work asked for from the control loop is posted to the
// lane. One request is with the Handler at a time (reading waits for it), so
// requests are answered in order, and a client flooding requests holds one
// body on the control loop, never a queue of them.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "gmr/server/config.h"
#include "gmr/wire/tls_socket.h"
#include "transport/net.h"
#include "transport/frame_queue.h"
#include "transport/io_threads.h"
#include "transport/outbox.h"

namespace prometheus {
class Histogram;
}

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
  int socket_send_buffer = 0;             // SO_SNDBUF; 0: the system's default
  int socket_unsent_bytes = 0;            // TCP_NOTSENT_LOWAT; 0: the system's default
};

// The limits cfg sets for each client connection.
inline ConnectionLimits connection_limits(const ServerConfig& cfg) {
  ConnectionLimits l;
  l.max_message_bytes = cfg.max_message_bytes;
  l.max_reply_queue_bytes = cfg.max_reply_queue_bytes;
  l.max_frame_bytes = cfg.max_frame_bytes_per_connection;
  l.frames_per_key = cfg.frames_per_subscription;
  l.idle_timeout = cfg.idle_timeout;
  l.handshake_timeout = cfg.handshake_timeout;
  l.heartbeat_interval = cfg.heartbeat_interval;
  l.write_timeout = cfg.write_timeout;
  l.congested_after = cfg.congested_after;
  l.socket_send_buffer = cfg.socket_send_buffer;
  l.socket_unsent_bytes = cfg.socket_unsent_bytes;
  return l;
}

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

// Where a connection runs: the control loop its Handler runs on (null: the
// connection's own io_context, one thread for everything), its lane's number
// (what stats report), and the server's I/O threads, through which writes
// the control loop asks for reach the lane in batches (null: posted one by
// one).
struct ConnectionPlacement {
  net::io_context* control = nullptr;
  std::size_t lane = 0;
  IoThreads* threads = nullptr;
};

class Connection final : public CountingOutbox, public std::enable_shared_from_this<Connection> {
 public:
  // What the connection hands its messages to (on the control loop).
  class Handler {
   public:
    virtual ~Handler() = default;
    // One whole message body (without its length prefix).
    virtual void on_message(const std::string& body) = 0;
    // The connection stopped (called once, before the socket closes).
    virtual void on_stop() = 0;
  };

  // `io`: the lane the socket belongs to. `budget` and `tls` (either may be
  // null) outlive the connection. With `tls` the connection speaks TLS: its
  // handshake comes first.
  Connection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
             BufferBudget* budget = nullptr, net::ssl::context* tls = nullptr, ConnectionPlacement placement = {});
  ~Connection() override;

  // Starts reading and the watchdog (on the lane). `on_closed` runs once,
  // on the control loop, when it stopped.
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
  std::size_t lane() const override { return lane_; }
  bool stopped() const override;
  bool closing() const override;
  void send(std::string framed) override;
  bool push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body,
                  Clock::duration max_age = {}) override;
  bool congested(std::uint32_t key) const override;
  void discard_frames(std::uint32_t key) override;
  void send_frames_now(std::uint32_t key) override;
  std::uint64_t end_frames(std::uint32_t key) override;
  void close_after_reply() override;
  void established() override;
  void hold_reading(bool hold) override;
  void count_udp_frame_sent() override;
  void count_udp_frame_dropped() override;
  void count_frame_dropped(std::uint64_t n) override;
  void count_frame_skipped(std::uint64_t n) override;
  const std::string& peer_address() const { return peer_address_; }
  // Observes, per write that carried frames, how long its oldest frame
  // waited from push_frame to the write's completion (seconds).
  void set_frame_wait_histogram(prometheus::Histogram* h) { frame_wait_ = h; }
  ConnectionCounters counters() const override;

 private:
  using Lock = std::lock_guard<std::recursive_mutex>;

  // Everything below runs with m_ held (but hand_over). On the lane only:
  // read_prefix, on_prefix, read_body, on_body, flush, arm_watchdog.
  bool on_lane() const { return io_.get_executor().running_in_this_thread(); }
  // Runs `f` on the lane (now, when this is the lane's thread).
  template <class F>
  void on_lane_do(F&& f);
  // A write, now on the lane or handed there once.
  void request_flush();
  void deferred_flush();  // on the lane, locks
  // Reading resumes (on the lane) when it was paused and may go on.
  void resume_reading();
  void read_prefix();
  void on_prefix(const boost::system::error_code& ec);
  void read_body();
  // A whole request body, for hand_over (called without m_).
  std::optional<std::string> on_body(const boost::system::error_code& ec, std::size_t got);
  // Gives a request to the Handler on the control loop; when it has
  // answered (handed_back), reading goes on.
  void hand_over(std::string body);
  void handed_back();
  void flush();
  void arm_watchdog();
  std::uint64_t queued_bytes() const { return reply_bytes_ + frames_.bytes() + in_flight_bytes_; }
  // Bytes held now (queued plus the request body being read) into the budget.
  void account();
  void note_queue();
  // Reading may go on: replies and the budget allow it.
  bool may_read() const;

  // Guards everything below that is not const after start(). Recursive: a
  // stop() may come from inside a locked step (a write that failed).
  mutable std::recursive_mutex m_;
  net::io_context& io_;
  net::io_context* control_;  // where the Handler and on_closed run
  std::size_t lane_;
  IoThreads* threads_;
  wire::TlsSocket socket_;
  std::uint64_t id_;
  ConnectionLimits limits_;
  std::string peer_;
  std::string peer_address_;  // the IP address alone
  bool established_ = false;
  Clock::time_point started_ = Clock::now();
  std::shared_ptr<Handler> handler_;
  std::function<void(std::uint64_t)> on_closed_;
  // Atomic: stopped() is read on every tick by each subscription's stream,
  // without the lock; set only under it.
  std::atomic<bool> stopped_{false};
  bool close_after_flush_ = false;
  bool close_on_next_reply_ = false;  // close_after_reply: the next send() closes after it
  bool read_paused_ = false;
  bool reads_held_ = false;  // hold_reading
  bool at_handler_ = false;  // a request body is with the Handler
  bool flush_posted_ = false;
  Clock::time_point flush_asked_{};  // when the pending flush was handed to the lane
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
