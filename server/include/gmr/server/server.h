// The streaming server: a TCP listener for requests and pushed frames, a UDP
// socket for registered endpoints, an HTTP port (the browser viewer, the same
// protocol over WebSocket, /metrics, /healthz, /readyz), and the library it
// serves.
//
//   client --TCP or WebSocket--> Connection --bodies--> RequestHandler --edits--> View (per connection)
//                      ^                        | subscribe
//                      | frames (TcpTarget)     v
//                   Stream (one FK + one encoding per tick) --UdpTarget--> UdpPublisher --> registered endpoint
//
// Requests, views and streams live on one thread, the control loop: per tick
// the work is one forward-kinematics pass and one encoding per stream, a few
// microseconds. The sockets' work (a send per subscriber per frame, most of a
// busy server's time) is spread over config.io_threads I/O threads, one of
// them the control loop. docs/architecture.md draws the whole data flow.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <vector>

#include "gmr/server/config.h"
#include "gmr/server/library.h"

namespace gmr::server {

struct SessionStats {
  std::uint64_t id = 0;
  std::uint64_t frames_sent = 0;
  std::uint64_t frames_dropped = 0;    // replaced by a newer frame before it was written, or UDP over its bound
  std::uint64_t frames_skipped = 0;    // ticks the server skipped because it was late
  std::uint64_t queued_bytes = 0;      // now: replies + frames waiting or being written
  std::uint64_t max_queued_bytes = 0;  // high-water mark
  bool udp_registered = false;
  std::size_t io_thread = 0;  // the I/O thread its socket work runs on (0: the control loop)
};

struct ServerStats {
  std::size_t connections = 0;
  std::size_t io_threads = 0;  // threads the sockets' work runs on, the control loop included
  std::size_t streams = 0;
  std::uint64_t frames_computed = 0;        // forward-kinematics runs for streams
  std::uint64_t frames_computed_float = 0;  // of those, by the float path (float32 streams)
  std::uint64_t fk_blocks_computed = 0;     // float path: blocks of 16 frames computed (FkBlocks)
  std::uint64_t fk_block_hits = 0;          // float path: frames read from a kept block
  std::size_t fk_block_bytes = 0;           // taken by the kept blocks
  std::uint64_t frames_encoded = 0;         // shared encodings
  std::uint64_t frames_skipped = 0;         // ticks skipped because the server was late, per subscriber
  std::uint64_t udp_rejected = 0;           // datagrams that were not a valid registration or confirm
  std::uint64_t udp_challenges = 0;         // challenges sent (one per valid registration datagram)
  std::uint64_t connections_refused = 0;
  std::uint64_t hellos_refused = 0;         // unknown token, or none where one is needed
  double committed_frames_per_second = 0;   // what all subscriptions ask for (against send_budget)
  double send_budget = 0;                   // config.send_budget, or what --send-budget auto measured (0: none)
  std::uint64_t subscriptions_refused = 0;  // refused for the send budget
  std::uint64_t publications_refused = 0;   // live sources refused for the send budget
  std::uint64_t relay_messages_refused = 0;
  bool relay_connected = false;          // --nats: NATS reached now
  std::uint64_t record_bytes = 0;        // now: the record budget recordings under way hold
  std::uint64_t recordings_refused = 0;  // Publish.record refused: no room in the record budget
  std::uint64_t recordings_cut = 0;      // recordings that stopped growing at a bound  // from NATS: unauthenticated,
                                         // unparsable, replayed or past the backlog
  std::uint64_t buffered_bytes = 0;      // now: all connections' replies, frames, writes, request bodies
  std::uint64_t max_buffered_bytes = 0;  // high-water mark of buffered_bytes
  std::uint64_t view_bytes = 0;          // now: motion bytes views own (edited copies) and live skeletons
  std::vector<SessionStats> sessions;
};

class Server {
 public:
  Server(ServerConfig config, std::vector<LibraryEntry> library);
  // A server whose library comes later (set_library): once started, HTTP
  // answers /healthz while /readyz says it is loading, and the TCP port
  // takes connections but reads them only once the library is there.
  explicit Server(ServerConfig config);
  ~Server();  // stop() and join
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds the TCP and UDP ports and starts the I/O threads. Throws
  // std::runtime_error naming the address when a port cannot be bound.
  void start();
  std::uint16_t tcp_port() const;
  std::uint16_t udp_port() const;
  // 0 when config.http_port is -1 (no HTTP).
  std::uint16_t http_port() const;

  // The library of a server made without one; the server is then ready
  // (/readyz). Called again (LibraryWatcher does it), the library is
  // replaced: entries of the same name and version are the same motion, and
  // the streams of a motion that changed (another version) or left end with
  // the reason; views made of it then refuse subscriptions and queries
  // (docs/protocol.md, "Library reload"). From any thread but the I/O thread.
  void set_library(std::vector<LibraryEntry> library);

  // Graceful stop: stops accepting, ends every stream, lets replies drain for
  // up to config.shutdown_grace, closes every connection, joins the I/O
  // thread. Idempotent; call from any thread but the I/O thread.
  void stop();
  // Blocks until the server has stopped.
  void wait();

  // New tokens (an auth file read again: gmr-server does it on SIGHUP).
  // Connections already past Hello keep their role; the next Hello is
  // checked against these. Null: no tokens, every client anonymous. Call
  // from any thread but the I/O thread; returns once the server uses them.
  void set_credentials(std::shared_ptr<const Credentials> credentials);

  // A snapshot taken on the I/O thread, waiting at most `timeout` for it
  // (then, or after stop(), what can be read without it: empty counters).
  ServerStats stats(std::chrono::milliseconds timeout = std::chrono::seconds(5)) const;

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace gmr::server
