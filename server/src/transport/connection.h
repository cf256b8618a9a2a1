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
// The outbox, its bounds and the watchdog's rules are QueuedOutbox's
// (queued_outbox.h), shared with WebSocket; this class is the socket's side.
// Replies held above max_reply_queue_bytes stop the read loop until they
// drain (a client that sends faster than it reads waits); a request body's
// length is reserved against the buffer budget before it is read (it waits
// in the kernel until the budget can take it), and its buffer grows as its
// bytes arrive. With TLS,
// the handshake comes before the first read.
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

#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "gmr/asio/tls_socket.h"
#include "transport/io_threads.h"
#include "transport/link.h"
#include "transport/net.h"
#include "transport/queued_outbox.h"

namespace gmr::server {

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

class Connection final : public QueuedOutbox, public std::enable_shared_from_this<Connection> {
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
  std::size_t lane() const override { return lane_; }
  const std::string& peer_address() const { return peer_address_; }

 private:
  // QueuedOutbox's transport part.
  void request_flush() override;
  void read_more() override;
  std::uint64_t reading_bytes() const override { return body_.size(); }
  bool link_ready() const override { return secured_; }

  // Everything below runs with m_ held (but hand_over). On the lane only:
  // read_next, on_read, take_buffered, read_body, on_body, flush, arm_watchdog.
  bool on_lane() const { return io_.get_executor().running_in_this_thread(); }
  // Runs `f` on the lane (now, when this is the lane's thread).
  template <class F>
  void on_lane_do(F&& f);
  void deferred_flush();  // on the lane, locks
  // The next request: one already read (a pipelined one goes to the
  // Handler), else a read of what arrived; nothing while reading may not go on.
  void read_next();
  // `got` bytes arrived in in_ (or the read failed: `ec`); a whole request
  // among them is returned for hand_over.
  std::optional<std::string> on_read(const boost::system::error_code& ec, std::size_t got);
  // The request whose length prefix starts at in_begin_: whole when its
  // body is in in_ too; else its body's read starts (or waits for the budget).
  std::optional<std::string> take_buffered();
  // The body's bytes in in_, then a read of the rest (or the whole body).
  std::optional<std::string> start_body();
  void read_body();
  // Reserves the announced body against the server's buffer budget; false when it cannot yet.
  bool reserve_body();
  // A whole request body, for hand_over (called without m_).
  std::optional<std::string> on_body(const boost::system::error_code& ec, std::size_t got);
  // `body` is whole: reading waits until the Handler has answered it.
  std::string finish_request(std::string body);
  // Gives a request to the Handler on the control loop; when it has
  // answered (handed_back), reading goes on. `inline_ok`: the caller holds
  // no lock, so a Handler on this thread may run at once (else it is posted).
  void hand_over(std::string body, bool inline_ok = true);
  void handed_back();
  void flush();
  // The write in flight goes on asynchronously (gather_: what is left of it;
  // `already`: bytes of it written at once).
  void write_rest(std::size_t already);
  // The write in flight completed (`ec`, `n` bytes of it written); the next
  // one starts.
  void wrote_all(const boost::system::error_code& ec, std::size_t n);
  void arm_watchdog() override;

  // Request bodies are read in chunks of at most this; a TLS write's copy
  // past it is given back.
  static constexpr std::size_t kBodyChunk = 256 * 1024;

  net::io_context& io_;
  net::io_context* control_;  // where the Handler and on_closed run
  std::size_t lane_;
  IoThreads* threads_;
  asio::TlsSocket socket_;
  std::string peer_;
  std::string peer_address_;  // the IP address alone
  std::shared_ptr<Handler> handler_;
  std::function<void(std::uint64_t)> on_closed_;
  // What arrived and was not taken yet (in_begin_ to in_end_): a small
  // request (a heartbeat, a subscription) comes in one read with its prefix,
  // and several sent at once are taken one by one without reading again.
  // At most this much is read ahead of the budget's reservation.
  static constexpr std::size_t kInBytes = 512;
  std::array<std::uint8_t, kInBytes> in_{};
  std::size_t in_begin_ = 0;
  std::size_t in_end_ = 0;
  std::string body_;
  std::size_t body_expected_ = 0;  // bytes the length prefix announced
  std::size_t body_received_ = 0;
  std::size_t body_reserved_ = 0;  // BufferBudget::reserved for the body being read
  bool body_waiting_ = false;      // announced, but the budget cannot take it yet

  // The write in flight: its buffers, and what they point into. Kept from
  // one write to the next (cleared, not freed), so a write allocates nothing.
  std::vector<net::const_buffer> gather_;
  std::vector<std::shared_ptr<const std::string>> hold_;
  std::vector<wire::FrameHead> hold_heads_;
  std::string tls_out_;   // with TLS: the write in flight in one piece (one record per 16 KiB, not per buffer)
  bool secured_ = false;  // the TLS handshake is done (or there is no TLS): writing may start
  net::steady_timer watchdog_;
};

}  // namespace gmr::server
