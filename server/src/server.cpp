#include "gmr/server/server.h"

#include <cmath>
#include <stdexcept>

#include <pthread.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include "calibrate.h"
#include "gmr/wire/framing.h"
#include "request_handler.h"
#include "server_state.h"

namespace gmr::server {

Server::Impl::Impl(ServerConfig config, std::vector<LibraryEntry> entries, bool is_ready)
    : cfg(std::move(config)), library(std::move(entries)), ready(is_ready) {
  for (std::size_t i = 0; i < library.size(); ++i) by_name.emplace(library[i].name, i);
}

void Server::Impl::install_library(std::vector<LibraryEntry> entries) {
  if (ready || stopping) return;
  library = std::move(entries);
  by_name.clear();
  for (std::size_t i = 0; i < library.size(); ++i) by_name.emplace(library[i].name, i);
  ready = true;
  spdlog::info("ready: {} motions", library.size());
  accept_loop();
}

std::shared_ptr<RequestHandler> Server::Impl::add_connection(const std::shared_ptr<Outbox>& outbox,
                                                             const std::string& address) {
  auto handler = std::make_shared<RequestHandler>(*this, outbox);
  handler->start();
  connections[outbox->id()] = ConnectionEntry{outbox, handler, address};
  pending_hello[outbox->id()] = outbox;
  ++per_address[address];
  ++accepted[outbox->transport()];
  return handler;
}

ConnectionLimits Server::Impl::connection_limits() const {
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

std::shared_ptr<const CompiledForm> Server::Impl::compiled_form(std::size_t entry) {
  if (compiled_forms.size() != library.size()) compiled_forms.resize(library.size());
  auto c = compiled_forms[entry].lock();
  if (!c) {
    c = std::make_shared<const CompiledForm>(library[entry].motion);
    compiled_forms[entry] = c;
  }
  return c;
}

void Server::Impl::connection_closed(std::uint64_t id) {
  auto it = connections.find(id);
  if (it == connections.end()) return;
  if (it->second.counted_on_lane) lanes->release(it->second.lane);
  if (auto c = it->second.connection.lock()) closed_counters[c->transport()].add_totals(c->counters());
  if (auto n = per_address.find(it->second.address); n != per_address.end() && --n->second == 0) per_address.erase(n);
  connections.erase(it);
  pending_hello.erase(id);
  if (stopping && connections.empty() && grace_timer) grace_timer->cancel();
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
      if (std::string why = admit(address); !why.empty()) {
        refuse(std::move(socket), why);
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
    // The descriptor moves to the lane's io_context: its reads, writes and
    // timers run on that thread from now on.
    boost::system::error_code ec;
    const auto protocol = socket.local_endpoint(ec).protocol();
    tcp::socket moved(lanes->io(lane));
    if (!ec) {
      const auto fd = socket.release(ec);
      if (!ec) {
        moved.assign(protocol, fd, ec);
        if (ec) ::close(fd);
      }
    }
    if (ec) {
      spdlog::warn("cannot move a connection to I/O thread {}: {}", lane, ec.message());
      lanes->release(lane);
      return;
    }
    socket = std::move(moved);
  }
  const std::uint64_t id = next_connection_id++;
  auto c = std::make_shared<Connection>(lanes->io(lane), std::move(socket), id, connection_limits(), &buffers,
                                        tls.get(), ConnectionPlacement{&io, lane, lanes.get()});
  c->set_frame_wait_histogram(&metrics.frame_wait(c->transport()));
  auto handler = add_connection(c, address);
  auto& entry = connections[id];
  entry.lane = lane;
  entry.counted_on_lane = true;
  c->start(std::move(handler), [this](std::uint64_t closed) { connection_closed(closed); });
}

std::string Server::Impl::admit(const std::string& address) {
  if (cfg.max_connections_per_address != 0) {
    auto it = per_address.find(address);
    if (it != per_address.end() && it->second >= cfg.max_connections_per_address) {
      return "the server's limit of " + std::to_string(cfg.max_connections_per_address) +
             " connections from one address (--max-connections-per-address)";
    }
  }
  // Connections still waiting for their Hello: past the cap, the oldest of
  // them gives way (it had its chance; a real client says Hello at once).
  while (!pending_hello.empty() && pending_hello.size() >= cfg.max_pending_handshakes) {
    const std::weak_ptr<Outbox> oldest = pending_hello.begin()->second;
    pending_hello.erase(pending_hello.begin());  // before stop(), whose connection_closed erases by id
    if (auto c = oldest.lock(); c && !c->stopped()) c->stop("made room for a new connection: no Hello yet");
  }
  if (connections.size() >= cfg.max_connections) {
    return "the server's limit of " + std::to_string(cfg.max_connections) + " connections (--max-connections)";
  }
  return {};
}

void Server::Impl::refuse(tcp::socket socket, const std::string& why) {
  ++connections_refused;
  if (std::uint64_t suppressed = 0; refusal_log.allow(suppressed)) {
    spdlog::warn("refusing a connection: {}{}", why,
                 suppressed ? " (" + std::to_string(suppressed) + " more refusals not logged)" : std::string());
  }
  auto bytes = std::make_shared<std::string>(
      wire::frame_message(error_message(0, pb::ERROR_CODE_RESOURCE_EXHAUSTED, "refused: " + why)).value());
  auto sock = std::make_shared<tcp::socket>(std::move(socket));
  net::async_write(*sock, net::buffer(*bytes), [sock, bytes](const boost::system::error_code&, std::size_t) {
    boost::system::error_code ignored;
    sock->shutdown(tcp::socket::shutdown_both, ignored);
    sock->close(ignored);
  });
}

void Server::Impl::begin_stop() {
  if (stopping) return;
  stopping = true;
  spdlog::info("stopping: {} connections, {} streams", connections.size(), streams.live());
  boost::system::error_code ec;
  acceptor.close(ec);
  http.close();
  udp.close();
  streams.stop_all();
  if (relay_timer) relay_timer->cancel();
  if (beacon_timer) beacon_timer->cancel();
  auto open = connections;
  for (auto& [id, entry] : open) {
    if (auto c = entry.connection.lock()) c->finish();
  }
  // Whatever has not drained by the deadline is closed; the io_context then runs out of work.
  if (connections.empty()) return;
  grace_timer = std::make_unique<net::steady_timer>(io, cfg.shutdown_grace);
  grace_timer->async_wait([this](const boost::system::error_code&) {
    auto left = connections;
    for (auto& [id, entry] : left) {
      if (auto c = entry.connection.lock()) c->stop("server shutdown");
    }
  });
}

ServerStats Server::Impl::snapshot() {
  ServerStats st;
  st.connections = connections.size();
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
  st.connections_refused = connections_refused;
  st.hellos_refused = auth_refused;
  st.committed_frames_per_second = static_cast<double>(committed_mhz) / 1000.0;
  st.send_budget = cfg.send_budget;
  st.subscriptions_refused = subscriptions_refused;
  st.buffered_bytes = buffers.held.load();
  st.max_buffered_bytes = buffers.max_held.load();
  st.view_bytes = view_bytes;
  for (auto& [id, entry] : connections) {
    auto c = entry.connection.lock();
    if (!c) continue;
    const ConnectionCounters k = c->counters();
    SessionStats s;
    s.id = id;
    s.frames_sent = k.frames_sent;
    s.frames_dropped = k.frames_dropped;
    s.frames_skipped = k.frames_skipped;
    s.queued_bytes = k.queued_bytes;
    s.max_queued_bytes = k.max_queued_bytes;
    s.io_thread = entry.lane;
    auto h = entry.handler.lock();
    s.udp_registered = h && h->udp()->endpoint.has_value();
    st.sessions.push_back(s);
  }
  return st;
}

// ---------------------------------------------------------------------------

Server::Server(ServerConfig config, std::vector<LibraryEntry> library)
    : impl_(std::make_shared<Impl>(std::move(config), std::move(library), true)) {}

Server::Server(ServerConfig config) : impl_(std::make_shared<Impl>(std::move(config), std::vector<LibraryEntry>{}, false)) {}

void Server::set_library(std::vector<LibraryEntry> library) {
  auto& d = *impl_;
  if (!d.started) {
    d.library = std::move(library);
    d.by_name.clear();
    for (std::size_t i = 0; i < d.library.size(); ++i) d.by_name.emplace(d.library[i].name, i);
    d.ready = true;
    return;
  }
  net::post(d.io, [impl = impl_.get(), entries = std::move(library)]() mutable {
    impl->install_library(std::move(entries));
  });
}

std::uint16_t Server::http_port() const { return impl_->http.port(); }

Server::~Server() { stop(); }

namespace {

// The TLS context of the server's certificate and key: TLS 1.2 or newer.
std::unique_ptr<net::ssl::context> make_tls_context(const ServerConfig& cfg) {
  if (cfg.tls_certificate_file.empty() && cfg.tls_key_file.empty()) return nullptr;
  if (cfg.tls_certificate_file.empty() || cfg.tls_key_file.empty()) {
    throw std::runtime_error("TLS needs both a certificate (--tls-cert) and its private key (--tls-key)");
  }
  auto ctx = std::make_unique<net::ssl::context>(net::ssl::context::tls_server);
  ctx->set_options(net::ssl::context::default_workarounds | net::ssl::context::no_sslv2 |
                   net::ssl::context::no_sslv3 | net::ssl::context::no_tlsv1 | net::ssl::context::no_tlsv1_1 |
                   net::ssl::context::single_dh_use);
  boost::system::error_code ec;
  ctx->use_certificate_chain_file(cfg.tls_certificate_file, ec);
  if (ec) {
    throw std::runtime_error("cannot use the TLS certificate " + cfg.tls_certificate_file + ": " + ec.message() +
                             " (a PEM certificate chain is expected)");
  }
  ctx->use_private_key_file(cfg.tls_key_file, net::ssl::context::pem, ec);
  if (ec) {
    throw std::runtime_error("cannot use the TLS private key " + cfg.tls_key_file + ": " + ec.message() +
                             " (a PEM private key matching the certificate is expected)");
  }
  return ctx;
}

}  // namespace

void Server::start() {
  auto& d = *impl_;
  if (d.started) throw std::runtime_error("server already started");
  if (d.cfg.calibrate_send_budget) {
    auto c = calibrate_send_budget();
    if (!c.ok()) throw std::runtime_error(c.error().to_string() + " (give --send-budget a figure)");
    d.cfg.send_budget = std::floor(c->budget);
    spdlog::info("send budget {:.0f} frames/s: a frame-sized TCP send costs {:.0f} ns here (the slowest of {} CPUs; "
                 "the fastest {:.0f}) against {:.0f} ns on the reference machine, which held {:.0f} (measured in "
                 "{:.2f} s; --send-budget N to set it)",
                 d.cfg.send_budget, c->ns_per_send, c->cpus, c->fastest_ns_per_send, kReferenceNsPerSend,
                 kReferenceBudget, c->seconds);
  }
  d.tls = make_tls_context(d.cfg);
  boost::system::error_code ec;
  const auto address = net::ip::make_address(d.cfg.bind_address, ec);
  if (ec) throw std::runtime_error("bad bind address '" + d.cfg.bind_address + "': " + ec.message());
  const tcp::endpoint tcp_ep(address, d.cfg.port);
  d.acceptor.open(tcp_ep.protocol());
  d.acceptor.set_option(tcp::acceptor::reuse_address(true));
  d.acceptor.bind(tcp_ep, ec);
  if (ec) throw std::runtime_error("cannot bind TCP " + d.cfg.bind_address + ":" + std::to_string(d.cfg.port) + ": " + ec.message());
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
    d.multicast = d.udp.open_multicast(d.cfg.multicast_group, d.cfg.multicast_port, d.cfg.multicast_ttl);
    spdlog::info("shared streams may go to multicast {}:{} (TTL {})", d.cfg.multicast_group, d.cfg.multicast_port,
                 d.cfg.multicast_ttl);
  }
  if (d.cfg.http_port >= 0) d.http.open(address, static_cast<std::uint16_t>(d.cfg.http_port));
  if (!address.is_loopback()) {
    if (!d.cfg.credentials || d.cfg.anonymous >= Role::kControl) {
      spdlog::warn("listening on {} without tokens: any host that can reach it may edit views and read "
                   "statistics; give --auth-file (docs/security.md), or --bind 127.0.0.1 (the default)",
                   d.cfg.bind_address);
    }
    if (!d.tls) {
      spdlog::warn("listening on {} without TLS: requests, frames{} cross the network in the clear "
                   "(--tls-cert and --tls-key, docs/security.md)",
                   d.cfg.bind_address, d.cfg.credentials ? " and tokens" : "");
    }
    if (d.http.port() != 0) {
      spdlog::warn("the HTTP port {} (viewer, WebSocket, /metrics) listens on {} in plain HTTP: WebSocket "
                   "tokens and frames cross the network in the clear; put a TLS proxy in front or use "
                   "--http-port -1 (docs/security.md)",
                   d.http.port(), d.cfg.bind_address);
    }
  }
  d.start_relay();
  d.start_beacon(address);
  d.started = true;
  if (d.ready) d.accept_loop();
  d.udp.start();
  d.http.start();
  spdlog::info("serving {} on tcp{} {}:{} and udp {}:{}{}{} ({} I/O thread{})",
               d.ready ? std::to_string(d.library.size()) + " motions" : std::string("(library loading)"),
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
  d.edit_pool.join();  // an edit still running finishes; its answer has no loop to run in
  if (d.relay) d.relay->stop();
  for (auto& r : d.recordings) r.wait();  // the I/O thread is done: nobody adds one
  d.recordings.clear();
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
