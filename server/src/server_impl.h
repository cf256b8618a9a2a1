// Server::Impl: the composition root. It owns every part of the server and is
// the only code that sees all of them; this header is included by server.cpp
// alone (tests/layout/check_layout.py checks it). The parts meet through
// narrow seams: a session sees Services (requests/services.h), a target its
// SubscriptionEvents, a stream the live source that feeds it, the HTTP port
// HttpServices, the relay a LiveDirectory. docs/architecture.md draws them.
//
//   Listener --accept--> Connection (TCP) ------+
//   HttpListener --/ws--> WsConnection (WebSocket) --bodies--> RequestHandler (views, subscriptions)
//     /metrics: Metrics, from a snapshot taken here                |  subscribe / edit
//                                                                  v
//   UdpPublisher <--UdpTarget-- Stream (one FK + one encoding per tick) --TcpTarget--> Connection or WsConnection
//                                 ^ kept and shared by StreamRegistry
//
// Touched only on the control loop (io), but for what says otherwise:
// connections live on their I/O threads (io_threads.h) and guard their own
// state; Admission::buffers is atomic.
#pragma once

#include <cmath>
#include <future>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "admission.h"
#include "catalog.h"
#include "gmr/server/server.h"
#include "http/http_server.h"
#include "http/metrics.h"
#include "live/recordings.h"
#include "live/replicas.h"
#include "requests/request_handler.h"
#include "requests/services.h"
#include "streams/fk_blocks.h"
#include "streams/stream_registry.h"
#include "streams/targets.h"
#include "transport/beacon.h"
#include "transport/budget_refresh.h"
#include "transport/calibrate.h"
#include "transport/connection.h"
#include "transport/io_threads.h"
#include "transport/net.h"
#include "transport/udp_publisher.h"

namespace gmr::server {

struct Server::Impl {
  Impl(ServerConfig config, std::vector<LibraryEntry> entries, bool ready);

  ServerConfig cfg;
  Catalog catalog;
  // The library is there (a server made without one waits for set_library):
  // /readyz says so, and TCP connections are accepted.
  bool ready = false;
  Metrics metrics;
  Recordings recordings{cfg};  // waited for by Server::wait()

  // Declared before io: connections that io's handlers still hold at
  // destruction give their bytes back to its budget.
  Admission admission{cfg};

  // The I/O threads (made by start()): lane 0 is io below. Declared before
  // io: what io's handlers still hold when it goes (connections) may own
  // sockets of the other lanes, which must outlive them.
  std::unique_ptr<IoThreads> lanes;
  net::io_context io;
  tcp::acceptor acceptor{io};
  UdpPublisher udp{io, cfg.max_udp_datagrams_in_flight};
  MulticastGroup multicast;
  FkBlocks fk_blocks{cfg.fk_cache_bytes};
  StreamCounters counters{.tick_lateness = &metrics.tick_lateness(), .fk_blocks = &fk_blocks};
  StreamRegistry streams{io, counters, cfg.tick_grid};
  Replicas replicas{io, cfg, catalog};
  Beacon beacon{io, cfg, [this] { return describe(); }};
  // Long view edits run here (RequestHandler::edit_view): one thread, so
  // edits queue rather than take the I/O thread's core. After io: joined
  // before io goes (a finished edit posts its answer to io).
  net::thread_pool edit_pool{1};
  // Live views' edits replayed on each published frame (LiveSource::set_replay):
  // a thread of their own, so a long edit does not hold live frames back.
  net::thread_pool live_pool{1};
  // WebSocket clients' large JSON replies are made here (WsConnection::kConvertAsideFrom).
  net::thread_pool json_pool{1};
  Services services{cfg, io,        edit_pool, catalog,    admission, streams, counters,
                    udp, multicast, replicas,  recordings, metrics,   lanes};
  // --send-budget auto: measured again on the edit thread over the first
  // minute, raising the budget when a measurement is faster (start() starts it).
  BudgetRefresh budget_refresh{io, edit_pool, &measure_send_budget,
                               [this](double budget) { cfg.send_budget = std::floor(budget); }};
  std::thread thread;
  std::uint16_t tcp_port = 0;
  bool started = false;
  bool stopping = false;
  std::promise<void> stopped;
  std::shared_future<void> stopped_future = stopped.get_future().share();

  HttpListener http{io, http_services()};
  // TLS (cfg.tls_certificate_file): made by start(), used by every connection.
  std::unique_ptr<net::ssl::context> tls;
  std::unique_ptr<net::steady_timer> grace_timer;  // while stopping

  HttpServices http_services();
  void accept_loop();
  // Registers an accepted client connection (TCP or WebSocket) with its
  // request handler; returns the handler, which the caller starts the
  // connection with.
  std::shared_ptr<RequestHandler> add_connection(const std::shared_ptr<Outbox>& outbox, const std::string& address);
  // An accepted TCP socket as a Connection on the least busy I/O thread.
  void accept_connection(tcp::socket socket, const std::string& address);
  // A WebSocket client the HTTP port admitted, on the control loop.
  void open_websocket(tcp::socket socket, http::request<http::string_body> upgrade, WsConnection::Format format,
                      const std::string& address);
  // Installs the library (set_library), on the I/O thread; once there, a
  // reloaded one replaces it (Catalog::reload).
  void install_library(std::vector<LibraryEntry> entries);
  void begin_stop();
  void connection_closed(std::uint64_t id);
  // What a discovery beacon says of this server.
  pb::Beacon describe() const;
  // Server::stats(); `sessions`: with each connection's figures.
  ServerStats snapshot(bool sessions = true);
  MetricsSnapshot metrics_snapshot();
};

}  // namespace gmr::server
