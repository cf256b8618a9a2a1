#include "gmr/server/server.h"

#include <cmath>
#include <stdexcept>

#include <pthread.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include "gmr/wire/framing.h"
#include "server_impl.h"
#include "transport/calibrate.h"
#include "transport/tls_context.h"
#include "transport/ws_connection.h"

namespace gmr::server {

Server::Impl::Impl(ServerConfig config, std::vector<LibraryEntry> entries, bool is_ready)
    : cfg(std::move(config)), catalog(std::move(entries)), ready(is_ready) {
  catalog.set_replay(live_pool.get_executor(), io.get_executor());
}

void Server::Impl::install_library(std::vector<LibraryEntry> entries) {
  if (stopping) return;
  if (ready) return catalog.reload(std::move(entries), streams);  // streams of what changed or left end
  catalog.set_library(std::move(entries));
  ready = true;
  spdlog::info("ready: {} motions", catalog.library().size());
  accept_loop();
}

std::shared_ptr<RequestHandler> Server::Impl::add_connection(const std::shared_ptr<Outbox>& outbox,
                                                             const std::string& address) {
  auto handler = std::make_shared<RequestHandler>(services, outbox);
  handler->start();
  admission.add(outbox, handler, address);
  return handler;
}

HttpServices Server::Impl::http_services() {
  return HttpServices{
      .cfg = cfg,
      .metrics = metrics,
      .status =
          [this] {
            return HttpServices::Status{stopping ? HttpServices::State::kStopping
                                        : ready  ? HttpServices::State::kReady
                                                 : HttpServices::State::kLoading,
                                        catalog.library().size()};
          },
      .metrics_text = [this] { return metrics.text(metrics_snapshot()); },
      .admit =
          [this](const std::string& address) {
            std::string why = admission.admit(address);
            if (!why.empty()) admission.refused(why, false);
            return why;
          },
      .open_websocket =
          [this](tcp::socket socket, http::request<http::string_body> upgrade, WsConnection::Format format,
                 const std::string& address) {
            open_websocket(std::move(socket), std::move(upgrade), format, address);
          },
  };
}

void Server::Impl::open_websocket(tcp::socket socket, http::request<http::string_body> upgrade,
                                  WsConnection::Format format, const std::string& address) {
  auto c = std::make_shared<WsConnection>(io, std::move(socket), admission.next_id(), connection_limits(cfg),
                                          &admission.buffers, json_pool.get_executor());
  c->set_frame_wait_histogram(&metrics.frame_wait(c->transport()));
  c->start(std::move(upgrade), format, add_connection(c, address),
           [this](std::uint64_t closed) { connection_closed(closed); });
}

void Server::Impl::connection_closed(std::uint64_t id) {
  const auto entry = admission.remove(id);
  if (!entry) return;
  if (entry->counted_on_lane) lanes->release(entry->lane);
  if (stopping && admission.connections().empty() && grace_timer) grace_timer->cancel();
}

void Server::Impl::accept_loop() {
  acceptor.async_accept([this](const boost::system::error_code& ec, tcp::socket socket) {
    if (ec) {
      if (ec == net::error::operation_aborted || stopping) return;
      spdlog::warn("accept failed: {}", ec.message());
    } else if (stopping) {
      return;
    } else {
      boost::system::error_code peer_ec;
      const auto peer = socket.remote_endpoint(peer_ec);
      const std::string address = peer_ec ? std::string("?") : peer.address().to_string();
      if (std::string why = admission.admit(address); !why.empty()) {
        admission.refused(why, true);
        refuse_socket(std::move(socket), error_message(0, pb::ERROR_CODE_RESOURCE_EXHAUSTED, "refused: " + why));
      } else {
        accept_connection(std::move(socket), address);
      }
    }
    accept_loop();
  });
}

void Server::Impl::accept_connection(tcp::socket socket, const std::string& address) {
  const std::size_t lane = lanes->assign();
  if (lane != 0) {
    boost::system::error_code ec;
    socket = lanes->adopt(std::move(socket), lane, ec);
    if (ec) {
      spdlog::warn("cannot move a connection to I/O thread {}: {}", lane, ec.message());
      lanes->release(lane);
      return;
    }
  }
  const std::uint64_t id = admission.next_id();
  auto c = std::make_shared<Connection>(lanes->io(lane), std::move(socket), id, connection_limits(cfg),
                                        &admission.buffers, tls.get(), ConnectionPlacement{&io, lane, lanes.get()});
  c->set_frame_wait_histogram(&metrics.frame_wait(c->transport()));
  auto handler = add_connection(c, address);
  Admission::Entry* entry = admission.find(id);
  entry->lane = lane;
  entry->counted_on_lane = true;
  c->start(std::move(handler), [this](std::uint64_t closed) { connection_closed(closed); });
}

void Server::Impl::begin_stop() {
  if (stopping) return;
  stopping = true;
  spdlog::info("stopping: {} connections, {} streams", admission.connections().size(), streams.live());
  boost::system::error_code ec;
  acceptor.close(ec);
  http.close();
  udp.close();
  streams.stop_all();
  replicas.stop();
  beacon.stop();
  budget_refresh.stop();
  auto open = admission.connections();
  for (auto& [id, entry] : open) {
    if (auto c = entry.connection.lock()) c->finish();
  }
  // Whatever has not drained by the deadline is closed; the io_context then runs out of work.
  if (admission.connections().empty()) return;
  grace_timer = std::make_unique<net::steady_timer>(io, cfg.shutdown_grace);
  grace_timer->async_wait([this](const boost::system::error_code&) {
    auto left = admission.connections();
    for (auto& [id, entry] : left) {
      if (auto c = entry.connection.lock()) c->stop("server shutdown");
    }
  });
}

pb::Beacon Server::Impl::describe() const {
  pb::Beacon b;
  b.set_protocol_version(wire::kProtocolVersion);
  b.set_server_name(cfg.server_name);
  b.set_tcp_port(tcp_port);
  b.set_udp_port(udp.port());
  b.set_http_port(http.port());
  b.set_tls(tls != nullptr);
  b.set_motions(static_cast<std::uint32_t>(catalog.library().size()));
  b.set_live_sources(static_cast<std::uint32_t>(catalog.live_sources().size()));
  if (multicast.group) {
    const auto& group = *multicast.group->endpoint;
    b.set_multicast_group(group.address().to_string() + ":" + std::to_string(group.port()));
  }
  return b;
}

ServerStats Server::Impl::snapshot(bool sessions) {
  ServerStats st;
  st.connections = admission.connections().size();
  st.io_threads = lanes ? lanes->size() : 1;
  st.streams = streams.active();
  st.frames_computed = counters.frames_computed;
  st.frames_computed_float = counters.frames_computed_float;
  st.fk_blocks_computed = fk_blocks.blocks_computed();
  st.fk_block_hits = fk_blocks.hits();
  st.fk_block_bytes = fk_blocks.bytes();
  st.frames_encoded = counters.frames_encoded;
  st.frames_skipped = counters.frames_skipped;
  st.udp_rejected = udp.rejected();
  st.udp_challenges = udp.challenges();
  st.connections_refused = admission.connections_refused();
  st.hellos_refused = admission.hellos_refused();
  st.committed_frames_per_second = admission.committed_frames_per_second();
  st.send_budget = cfg.send_budget;
  st.subscriptions_refused = admission.subscriptions_refused();
  st.publications_refused = admission.publications_refused();
  st.relay_messages_refused = replicas.messages_refused();
  st.relay_connected = replicas.relay_connected();
  st.record_bytes = recordings.budget().held();
  st.recordings_refused = recordings.budget().refused();
  st.recordings_cut = recordings.budget().cut();
  st.buffered_bytes = admission.buffers.held.load();
  st.max_buffered_bytes = admission.buffers.max_held.load();
  st.view_bytes = admission.view_bytes();
  if (sessions) st.sessions = admission.session_stats();
  return st;
}

MetricsSnapshot Server::Impl::metrics_snapshot() {
  MetricsSnapshot s;
  s.server = snapshot(false);
  s.ready = ready && !stopping;
  s.library_motions = catalog.library().size();
  const Admission::Holdings held = admission.holdings();
  s.open_connections = held.connections;
  s.views = held.views;
  s.subscriptions = held.subscriptions;
  s.accepted_connections = admission.accepted();
  s.connection_totals = admission.totals_by_transport();
  s.client_frame_wait_p99 = admission.frame_wait_p99s();
  for (std::size_t k = 0; lanes && k < lanes->size(); ++k) s.lane_connections.push_back(lanes->connections(k));
  s.udp_bytes_sent = udp.bytes_sent();
  s.multicast_frames_sent = multicast.frames_sent;
  s.live_sources = catalog.live_sources().size();
  s.live_frames_received = catalog.live_frames_received();
  s.live_frames_refused = catalog.live_frames_refused();
  s.live_frames_over_rate = catalog.live_frames_over_rate();
  s.live_edit_replays = catalog.live_edit_replays();
  s.live_markers = catalog.live_markers();
  s.library_reloads = catalog.reloads();
  s.library_changes = catalog.library_changes();
  s.relay_announces_refused = replicas.announces_refused();
  return s;
}

Server::Server(ServerConfig config, std::vector<LibraryEntry> library)
    : impl_(std::make_shared<Impl>(std::move(config), std::move(library), true)) {}

Server::Server(ServerConfig config)
    : impl_(std::make_shared<Impl>(std::move(config), std::vector<LibraryEntry>{}, false)) {}

void Server::set_library(std::vector<LibraryEntry> library) {
  auto& d = *impl_;
  if (!d.started) {
    d.catalog.set_library(std::move(library));
    d.ready = true;
    return;
  }
  net::post(d.io, [impl = impl_.get(), entries = std::move(library)]() mutable {
    impl->install_library(std::move(entries));
  });
}

std::uint16_t Server::http_port() const { return impl_->http.port(); }

Server::~Server() { stop(); }

void Server::start() {
  auto& d = *impl_;
  if (d.started) throw std::runtime_error("server already started");
  if (d.cfg.calibrate_send_budget) {
    auto c = calibrate_send_budget();
    if (!c.ok()) throw std::runtime_error(c.error().to_string() + " (give --send-budget a figure)");
    d.cfg.send_budget = std::floor(c->budget);
    spdlog::info(
        "send budget {:.0f} frames/s: a frame-sized TCP send costs {:.0f} ns here (the fastest of {} CPUs; "
        "the slowest {:.0f}) against {:.0f} ns on the reference machine, which held {:.0f} (measured in "
        "{:.2f} s; --send-budget N to set it)",
        d.cfg.send_budget, c->fastest_ns_per_send, c->cpus, c->ns_per_send, kReferenceNsPerSend, kReferenceBudget,
        c->seconds);
    d.budget_refresh.start(d.cfg.send_budget);  // before io runs: nothing else touches it yet
  }
  d.tls = make_tls_context(d.cfg);
  boost::system::error_code ec;
  const auto address = net::ip::make_address(d.cfg.bind_address, ec);
  if (ec) throw std::runtime_error("bad bind address '" + d.cfg.bind_address + "': " + ec.message());
  const tcp::endpoint tcp_ep(address, d.cfg.port);
  d.acceptor.open(tcp_ep.protocol());
  d.acceptor.set_option(tcp::acceptor::reuse_address(true));
  d.acceptor.bind(tcp_ep, ec);
  if (ec)
    throw std::runtime_error("cannot bind TCP " + d.cfg.bind_address + ":" + std::to_string(d.cfg.port) + ": " +
                             ec.message());
  d.acceptor.listen(net::socket_base::max_listen_connections);
  d.tcp_port = d.acceptor.local_endpoint().port();
  // The same number as TCP only when that number was chosen: an ephemeral TCP
  // port's number may well be taken for UDP, so then UDP gets its own.
  const std::uint16_t udp_port = d.cfg.udp_port >= 0 ? static_cast<std::uint16_t>(d.cfg.udp_port)
                                 : d.cfg.port == 0   ? std::uint16_t{0}
                                                     : d.tcp_port;
  d.lanes = std::make_unique<IoThreads>(d.io, io_thread_count(d.cfg.io_threads));
  d.udp.set_congested_after(d.cfg.congested_after);
  d.udp.open(address, udp_port, d.lanes.get());
  if (!d.cfg.multicast_group.empty()) {
    d.multicast.group = d.udp.open_multicast(d.cfg.multicast_group, d.cfg.multicast_port, d.cfg.multicast_ttl);
    spdlog::info("shared streams may go to multicast {}:{} (TTL {})", d.cfg.multicast_group, d.cfg.multicast_port,
                 d.cfg.multicast_ttl);
  }
  if (d.cfg.http_port >= 0) d.http.open(address, static_cast<std::uint16_t>(d.cfg.http_port));
  if (!address.is_loopback()) {
    if (!d.cfg.credentials || d.cfg.anonymous >= Role::kControl) {
      spdlog::warn(
          "listening on {} without tokens: any host that can reach it may edit views and read "
          "statistics; give --auth-file (docs/security.md), or --bind 127.0.0.1 (the default)",
          d.cfg.bind_address);
    }
    if (!d.tls) {
      spdlog::warn(
          "listening on {} without TLS: requests, frames{} cross the network in the clear "
          "(--tls-cert and --tls-key, docs/security.md)",
          d.cfg.bind_address, d.cfg.credentials ? " and tokens" : "");
    }
    if (d.http.port() != 0) {
      spdlog::warn(
          "the HTTP port {} (viewer, WebSocket, /metrics) listens on {} in plain HTTP: WebSocket "
          "tokens and frames cross the network in the clear; put a TLS proxy in front or use "
          "--http-port -1 (docs/security.md)",
          d.http.port(), d.cfg.bind_address);
    }
  }
  d.replicas.start();
  d.beacon.start(address);
  d.started = true;
  if (d.ready) d.accept_loop();
  d.udp.start();
  d.http.start();
  spdlog::info(
      "serving {} on tcp{} {}:{} and udp {}:{}{}{} ({} I/O thread{})",
      d.ready ? std::to_string(d.catalog.library().size()) + " motions" : std::string("(library loading)"),
      d.tls ? " (TLS)" : "", d.cfg.bind_address, d.tcp_port, d.cfg.bind_address, d.udp.port(),
      d.http.port() != 0 ? ", http " + d.cfg.bind_address + ":" + std::to_string(d.http.port()) : std::string(),
      d.cfg.credentials ? ", " + std::to_string(d.cfg.credentials->size()) + " tokens, anonymous clients " +
                              role_name(d.cfg.anonymous)
                        : std::string(),
      d.lanes->size(), d.lanes->size() == 1 ? "" : "s");
  d.lanes->start();
  d.thread = std::thread([impl = impl_] {
    ::pthread_setname_np(::pthread_self(), "gmr-control");  // lane 0: requests, streams, and its connections
    try {
      impl->io.run();
    } catch (const std::exception& e) {
      spdlog::critical("I/O thread stopped: {}", e.what());
    }
    impl->stopped.set_value();
  });
}

std::uint16_t Server::tcp_port() const { return impl_->tcp_port; }
std::uint16_t Server::udp_port() const { return impl_->udp.port(); }

void Server::stop() {
  auto& d = *impl_;
  if (!d.started) return;
  // A raw pointer: a handler that never runs (the loop already ended) must
  // not keep Impl, which owns the io_context holding it, alive.
  net::post(d.io, [impl = impl_.get()] { impl->begin_stop(); });
  wait();
}

void Server::wait() {
  auto& d = *impl_;
  if (!d.started) return;
  d.stopped_future.wait();
  if (d.thread.joinable()) d.thread.join();
  if (d.lanes) d.lanes->join();  // their connections closed with the control loop's last work
  d.edit_pool.join();            // an edit still running finishes; its answer has no loop to run in
  d.live_pool.join();            // so does a replay
  d.replicas.close();
  d.recordings.wait();  // the I/O thread is done: nobody adds one
}

void Server::set_credentials(std::shared_ptr<const Credentials> credentials) {
  auto& d = *impl_;
  if (!d.started || d.stopped_future.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    d.cfg.credentials = std::move(credentials);
    return;
  }
  auto done = std::make_shared<std::promise<void>>();
  auto f = done->get_future();
  net::post(d.io, [done, impl = impl_.get(), c = std::move(credentials)]() mutable {
    impl->cfg.credentials = std::move(c);
    done->set_value();
  });
  // The loop may end before it runs the handler (a stop under way): then
  // nobody says Hello any more.
  while (f.wait_for(std::chrono::milliseconds(50)) != std::future_status::ready) {
    if (d.stopped_future.wait_for(std::chrono::seconds(0)) == std::future_status::ready) return;
  }
}

ServerStats Server::stats(std::chrono::milliseconds timeout) const {
  auto& d = *impl_;
  if (!d.started || d.stopped_future.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    return d.snapshot();
  }
  // The promise is shared with the posted handler: when the I/O thread is
  // finishing a stop and runs it late (or never), this call may already
  // have returned.
  auto p = std::make_shared<std::promise<ServerStats>>();
  auto f = p->get_future();
  net::post(d.io, [p, impl = impl_.get()] { p->set_value(impl->snapshot()); });
  if (f.wait_for(timeout) != std::future_status::ready) return {};
  return f.get();
}

}  // namespace gmr::server
