#include "gmr/server/server.h"

#include <stdexcept>

#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"
#include "server_impl.h"
#include "session.h"
#include "stream.h"

namespace gmr::server {


// ---------------------------------------------------------------------------
// Listener and UDP registration

void Server::Impl::accept_loop() {
  acceptor.async_accept([this](const boost::system::error_code& ec, tcp::socket socket) {
    if (ec) {
      if (ec == net::error::operation_aborted || stopping) return;
      spdlog::warn("accept failed: {}", ec.message());
    } else if (stopping) {
      return;
    } else if (sessions.size() >= cfg.max_connections) {
      ++connections_refused;
      spdlog::warn("refusing a connection: {} connections open (--max-connections)", sessions.size());
      auto bytes = std::make_shared<std::string>(
          wire::frame_message(error_message(0, pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                                            "the server has reached its limit of " +
                                                std::to_string(cfg.max_connections) + " connections"))
              .value());
      auto sock = std::make_shared<tcp::socket>(std::move(socket));
      net::async_write(*sock, net::buffer(*bytes), [sock, bytes](const boost::system::error_code&, std::size_t) {
        boost::system::error_code ignored;
        sock->shutdown(tcp::socket::shutdown_both, ignored);
        sock->close(ignored);
      });
    } else {
      const std::uint64_t id = next_session_id++;
      auto s = std::make_shared<Session>(*this, std::move(socket), id);
      sessions[id] = s;
      s->start();
    }
    accept_loop();
  });
}

void Server::Impl::udp_loop() {
  udp_socket.async_receive_from(net::buffer(udp_buffer), udp_sender, [this](const boost::system::error_code& ec,
                                                                            std::size_t n) {
    if (ec == net::error::operation_aborted || stopping) return;
    if (!ec) {
      const auto token = wire::parse_register_datagram(std::string_view(udp_buffer.data(), n));
      std::shared_ptr<Session> s;
      if (token) {
        if (auto it = tokens.find(*token); it != tokens.end()) s = it->second.lock();
      }
      if (s && !s->stopped()) {
        s->udp_registered(udp_sender);
      } else {
        // Never answer: an unregistered address gets nothing from this server.
        if (udp_rejected++ % 1000 == 0) {
          spdlog::warn("ignoring a {}-byte UDP datagram from {}:{}: {} ({} so far)", n,
                       udp_sender.address().to_string(), udp_sender.port(),
                       token ? "unknown session token" : "not a registration datagram", udp_rejected);
        }
      }
    }
    udp_loop();
  });
}

void Server::Impl::begin_stop() {
  if (stopping) return;
  stopping = true;
  prune_streams();
  spdlog::info("stopping: {} connections, {} streams", sessions.size(), streams.size());
  boost::system::error_code ec;
  acceptor.close(ec);
  udp_socket.close(ec);
  for (auto& [id, weak] : streams) {
    if (auto s = weak.lock()) s->stop();
  }
  auto open = sessions;
  for (auto& [id, weak] : open) {
    if (auto s = weak.lock()) s->finish();
  }
  // Whatever has not drained by the deadline is closed; the io_context then runs out of work.
  if (sessions.empty()) return;
  grace_timer = std::make_unique<net::steady_timer>(io, cfg.shutdown_grace);
  grace_timer->async_wait([this](const boost::system::error_code&) {
    auto left = sessions;
    for (auto& [id, weak] : left) {
      if (auto s = weak.lock()) s->stop("server shutdown");
    }
  });
}

ServerStats Server::Impl::snapshot() const {
  ServerStats st;
  st.connections = sessions.size();
  for (auto& [id, w] : streams) {
    if (auto s = w.lock(); s && !s->targets().empty()) ++st.streams;
  }
  st.frames_computed = frames_computed;
  st.frames_computed_float = frames_computed_float;
  st.frames_encoded = frames_encoded;
  st.udp_rejected = udp_rejected;
  st.connections_refused = connections_refused;
  for (auto& [id, w] : sessions) {
    if (auto s = w.lock()) st.sessions.push_back(s->stats());
  }
  return st;
}

// ---------------------------------------------------------------------------

Server::Server(ServerConfig config, std::vector<LibraryEntry> library) : impl_(std::make_shared<Impl>()) {
  impl_->cfg = std::move(config);
  impl_->library = std::move(library);
  for (std::size_t i = 0; i < impl_->library.size(); ++i) impl_->by_name.emplace(impl_->library[i].name, i);
}

Server::~Server() { stop(); }

void Server::start() {
  auto& d = *impl_;
  if (d.started) throw std::runtime_error("server already started");
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
  const std::uint16_t udp_port = d.cfg.udp_port < 0 ? d.tcp_port : static_cast<std::uint16_t>(d.cfg.udp_port);
  const udp::endpoint udp_ep(address, udp_port);
  d.udp_socket.open(udp_ep.protocol());
  d.udp_socket.bind(udp_ep, ec);
  if (ec) throw std::runtime_error("cannot bind UDP " + d.cfg.bind_address + ":" + std::to_string(udp_port) + ": " + ec.message());
  d.udp_port = d.udp_socket.local_endpoint().port();
  d.started = true;
  d.accept_loop();
  d.udp_loop();
  spdlog::info("serving {} motions on tcp {}:{} and udp {}:{}", d.library.size(), d.cfg.bind_address, d.tcp_port,
               d.cfg.bind_address, d.udp_port);
  d.thread = std::thread([impl = impl_] {
    try {
      impl->io.run();
    } catch (const std::exception& e) {
      spdlog::critical("I/O thread stopped: {}", e.what());
    }
    impl->stopped.set_value();
  });
}

std::uint16_t Server::tcp_port() const { return impl_->tcp_port; }
std::uint16_t Server::udp_port() const { return impl_->udp_port; }

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
}

ServerStats Server::stats() const {
  auto& d = *impl_;
  if (!d.started || d.stopped_future.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    return d.snapshot();
  }
  std::promise<ServerStats> p;
  auto f = p.get_future();
  net::post(d.io, [&] { p.set_value(d.snapshot()); });
  // The I/O thread may be finishing a stop and never run the snapshot.
  if (f.wait_for(std::chrono::seconds(5)) != std::future_status::ready) return {};
  return f.get();
}

}  // namespace gmr::server
