// Discovery beacons: a server started with --discovery-group says, every
// second, on a multicast group, who it is and where it listens; `gmr
// discover` hears them. A documented UDP beacon in the manner of NatNet's
// rather than DNS-SD: see docs/protocol.md, "Discovery", for why.
#include <spdlog/spdlog.h>

#include "gmr/wire/framing.h"
#include "server_state.h"

namespace gmr::server {

void Server::Impl::start_beacon(const net::ip::address& bound) {
  if (cfg.discovery_group.empty()) return;
  boost::system::error_code ec;
  const auto group = net::ip::make_address_v4(cfg.discovery_group, ec);
  if (ec || !group.is_multicast()) {
    throw std::runtime_error("--discovery-group " + cfg.discovery_group +
                             " is not an IPv4 multicast address (224.0.0.0/4)");
  }
  beacon_group = net::ip::udp::endpoint(group, cfg.discovery_port);
  beacon_socket = std::make_unique<net::ip::udp::socket>(io);
  beacon_socket->open(net::ip::udp::v4(), ec);
  if (!ec) beacon_socket->set_option(net::ip::multicast::hops(cfg.multicast_ttl), ec);
  if (!ec && bound.is_v4() && !bound.is_unspecified()) {
    beacon_socket->set_option(net::ip::multicast::outbound_interface(bound.to_v4()), ec);
  }
  if (!ec) beacon_socket->set_option(net::ip::multicast::enable_loopback(true), ec);
  if (ec) throw std::runtime_error("cannot send discovery beacons to " + cfg.discovery_group + ": " + ec.message());
  beacon_timer = std::make_unique<net::steady_timer>(io);
  spdlog::info("discovery beacons to {}:{} every {} ms", cfg.discovery_group, cfg.discovery_port,
               cfg.discovery_interval.count());
  send_beacon();
}

void Server::Impl::send_beacon() {
  if (stopping) return;
  pb::Beacon b;
  b.set_protocol_version(wire::kProtocolVersion);
  b.set_server_name(cfg.server_name);
  b.set_tcp_port(tcp_port);
  b.set_udp_port(udp.port());
  b.set_http_port(http.port());
  b.set_tls(tls != nullptr);
  b.set_motions(static_cast<std::uint32_t>(library.size()));
  b.set_live_sources(static_cast<std::uint32_t>(live.size()));
  if (multicast) {
    b.set_multicast_group(multicast->endpoint->address().to_string() + ":" + std::to_string(multicast->endpoint->port()));
  }
  const std::string datagram = "GMRB" + b.SerializeAsString();
  boost::system::error_code ec;
  beacon_socket->send_to(net::buffer(datagram), beacon_group, 0, ec);
  if (ec) spdlog::debug("discovery beacon not sent: {}", ec.message());
  beacon_timer->expires_after(cfg.discovery_interval);
  beacon_timer->async_wait([this](const boost::system::error_code& e) {
    if (!e) send_beacon();
  });
}

}  // namespace gmr::server
