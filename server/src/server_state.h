// Private to the server: what the listener, the request handlers and the
// streams share. Touched only on the control loop (io), but for what says
// otherwise: connections live on their I/O threads (io_threads.h) and guard
// their own state; `buffers` is atomic.
//
//   Listener --accept--> Connection (TCP) ------+
//   HttpListener --/ws--> WsConnection (WebSocket) --bodies--> RequestHandler (views, subscriptions)
//     /metrics: Metrics, read from here                           |  subscribe / edit
//                                                                 v
//   UdpPublisher <--UdpTarget-- Stream (one FK + one encoding per tick) --TcpTarget--> Connection or WsConnection
//                                 ^ kept and shared by StreamRegistry
#pragma once

#include <algorithm>
#include <future>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "connection.h"
#include "fk_blocks.h"
#include "http_server.h"
#include "io_threads.h"
#include "live.h"
#include "relay.h"
#include "targets.h"
#include "metrics.h"
#include "gmr/server/server.h"
#include "gmr/server/view.h"
#include "net.h"
#include "stream_registry.h"
#include "udp_publisher.h"

namespace gmr::server {

class RequestHandler;

// Stream parameters: beyond these the schedule arithmetic loses meaning (or
// one stream could monopolise the I/O thread).
constexpr double kMinSpeed = 1e-3, kMaxSpeed = 1000.0;
constexpr double kMinRateHz = 1e-2, kMaxRateHz = 10000.0;

struct Server::Impl {
  Impl(ServerConfig config, std::vector<LibraryEntry> entries, bool ready);

  ServerConfig cfg;
  std::vector<LibraryEntry> library;
  // The library is there (a server made without one waits for set_library):
  // /readyz says so, and TCP connections are accepted.
  bool ready = false;
  Metrics metrics;
  std::map<std::string, std::size_t, std::less<>> by_name;
  // Live sources being published (docs/protocol.md, "Live sources"), by
  // name; a source leaves when its publication ends.
  std::map<std::string, std::shared_ptr<LiveSource>, std::less<>> live;
  std::uint64_t next_live_serial = 1;
  std::uint64_t live_frames_received = 0;  // frames published and accepted, all sources
  std::uint64_t live_frames_refused = 0;   // PublishFrame refused (wrong size, not finite)
  // Recordings of live sources being written (off the I/O thread); wait()
  // waits for them.
  std::vector<std::future<void>> recordings;
  // Multicast (cfg.multicast_group): the group's registration, and each
  // shared stream's channel to it, by stream id.
  std::shared_ptr<UdpPublisher::Registration> multicast;
  std::map<std::uint64_t, std::weak_ptr<MulticastChannel>> multicast_channels;
  std::uint64_t multicast_frames_sent = 0;
  // Discovery beacons (cfg.discovery_group; discovery.cpp); the socket and
  // timer are declared after io.
  net::ip::udp::endpoint beacon_group;
  void start_beacon(const net::ip::address& bound);
  void send_beacon();
  // Replicas: the NATS relay (cfg.nats_url), and the live sources other
  // replicas publish, by origin and serial (replicas.cpp). The relay posts
  // to io only until Server::wait() stops it.
  std::unique_ptr<NatsRelay> relay;
  struct RemoteSource {
    std::shared_ptr<LiveSource> source;  // null: ignored (its name is taken here)
    Clock::time_point heard;
  };
  std::map<std::string, RemoteSource> remote_sources;  // at most cfg.max_remote_sources
  std::uint64_t relay_announces_refused = 0;  // invalid, or past max_remote_sources
  LogLimiter relay_log_limit;                 // lines other replicas' messages may put in the log
  void start_relay();
  void relay_tick();
  void on_relay(relay_pb::LiveRelay m);
  // A source published here: tell the other replicas.
  void relay_announce(const LiveSource& source);
  void relay_frame(const LiveSource& source, std::span<const double> values);
  void relay_end(const LiveSource& source, const std::string& reason);

  // Declared before io: connections that io's handlers still hold at
  // destruction give their bytes back to it.
  BufferBudget buffers{cfg.max_buffered_bytes, cfg.max_buffered_bytes / std::max<std::size_t>(1, cfg.max_connections)};
  // Bytes of motions that views own (edited copies, docs/protocol.md).
  std::uint64_t view_bytes = 0;
  // Frames per second the subscriptions ask for, in millihertz (integers:
  // no drift however many come and go), against cfg.send_budget.
  std::uint64_t committed_mhz = 0;
  std::uint64_t subscriptions_refused = 0;  // for the send budget

  // The I/O threads (made by start()): lane 0 is io below. Declared before
  // io: what io's handlers still hold when it goes (connections) may own
  // sockets of the other lanes, which must outlive them.
  std::unique_ptr<IoThreads> lanes;
  net::io_context io;
  tcp::acceptor acceptor{io};
  UdpPublisher udp{io, cfg.max_udp_datagrams_in_flight};
  FkBlocks fk_blocks{cfg.fk_cache_bytes};
  StreamCounters counters{.tick_lateness = &metrics.tick_lateness(), .fk_blocks = &fk_blocks};
  StreamRegistry streams{io, counters};
  // After io: destroyed before it.
  std::unique_ptr<net::ip::udp::socket> beacon_socket;
  std::unique_ptr<net::steady_timer> beacon_timer;
  std::unique_ptr<net::steady_timer> relay_timer;
  // Long view edits run here (RequestHandler::edit_view): one thread, so
  // edits queue rather than take the I/O thread's core. After io: joined
  // before io goes (a finished edit posts its answer to io).
  net::thread_pool edit_pool{1};
  std::thread thread;
  std::uint16_t tcp_port = 0;
  bool started = false;
  bool stopping = false;
  std::promise<void> stopped;
  std::shared_future<void> stopped_future = stopped.get_future().share();

  HttpListener http{*this};
  std::uint64_t next_connection_id = 1;
  struct ConnectionEntry {
    std::weak_ptr<Outbox> connection;
    std::weak_ptr<RequestHandler> handler;
    std::string address;  // the client's IP address
    std::size_t lane = 0;  // its I/O thread (WebSocket clients are on the control loop)
    bool counted_on_lane = false;  // IoThreads::assign counted it (TCP)
  };
  std::map<std::uint64_t, ConnectionEntry> connections;
  std::map<std::string, std::size_t> per_address;  // open connections by IP address
  // Connections waiting for their Hello, by id: ids grow, so the first is
  // the oldest (admit() pushes it out past max_pending_handshakes).
  std::map<std::uint64_t, std::weak_ptr<Outbox>> pending_hello;
  // Connections accepted, by transport, and the counters of those closed
  // (metrics add the open ones'), for lifetime totals.
  std::map<std::string, std::uint64_t, std::less<>> accepted;
  std::map<std::string, ConnectionCounters, std::less<>> closed_counters;
  std::uint64_t connections_refused = 0;
  LogLimiter refusal_log{5, std::chrono::seconds(10)};
  // Hello refused for its token (or for having none).
  std::uint64_t auth_refused = 0;
  LogLimiter auth_log{5, std::chrono::seconds(10)};
  // TLS (cfg.tls_certificate_file): made by start(), used by every connection.
  std::unique_ptr<net::ssl::context> tls;
  // Per library entry: the float form its unedited views share, while any
  // view holds it (compiled on first use by a float32 stream; freed with the
  // last view, so memory follows what is being streamed).
  std::vector<std::weak_ptr<const CompiledForm>> compiled_forms;
  std::unique_ptr<net::steady_timer> grace_timer;  // while stopping

  // The connection limits of cfg.
  ConnectionLimits connection_limits() const;
  void accept_loop();
  // Why a new connection from `address` is refused (empty: admit it). May
  // close the oldest connection still waiting for its Hello to make room.
  std::string admit(const std::string& address);
  void refuse(tcp::socket socket, const std::string& why);
  // Registers an accepted client connection (TCP or WebSocket) with its
  // request handler; returns the handler, which the caller starts the
  // connection with.
  std::shared_ptr<RequestHandler> add_connection(const std::shared_ptr<Outbox>& outbox, const std::string& address);
  // An accepted TCP socket as a Connection on the least busy I/O thread.
  void accept_connection(tcp::socket socket, const std::string& address);
  // Installs the library (set_library), on the I/O thread.
  void install_library(std::vector<LibraryEntry> entries);
  void begin_stop();
  void connection_closed(std::uint64_t id);
  // The shared float form of library entry `entry` (made when no view holds one).
  std::shared_ptr<const CompiledForm> compiled_form(std::size_t entry);
  ServerStats snapshot();
};

}  // namespace gmr::server
