#include "transport/beacon.h"

#include <spdlog/spdlog.h>

#include <stdexcept>
#include <string>

namespace gmr::server {

Beacon::Beacon(net::io_context& io, const ServerConfig& cfg, std::function<pb::Beacon()> describe)
    : io_(io), cfg_(cfg), describe_(std::move(describe)) {}

void Beacon::start(const net::ip::address& bound) {
  if (cfg_.discovery_group.empty()) return;
  boost::system::error_code ec;
  const auto group = net::ip::make_address_v4(cfg_.discovery_group, ec);
  if (ec || !group.is_multicast()) {
    throw std::runtime_error("--discovery-group " + cfg_.discovery_group +
                             " is not an IPv4 multicast address (224.0.0.0/4)");
  }
  group_ = net::ip::udp::endpoint(group, cfg_.discovery_port);
  socket_ = std::make_unique<net::ip::udp::socket>(io_);
  socket_->open(net::ip::udp::v4(), ec);
  if (!ec) socket_->set_option(net::ip::multicast::hops(cfg_.multicast_ttl), ec);
  if (!ec && bound.is_v4() && !bound.is_unspecified()) {
    socket_->set_option(net::ip::multicast::outbound_interface(bound.to_v4()), ec);
  }
  if (!ec) socket_->set_option(net::ip::multicast::enable_loopback(true), ec);
  if (ec) throw std::runtime_error("cannot send discovery beacons to " + cfg_.discovery_group + ": " + ec.message());
  timer_ = std::make_unique<net::steady_timer>(io_);
  spdlog::info("discovery beacons to {}:{} every {} ms", cfg_.discovery_group, cfg_.discovery_port,
               cfg_.discovery_interval.count());
  if (const auto why = multicast_unreachable(bound, group); !why.empty()) {
    spdlog::warn("discovery beacons will reach no one: {}", why);
  }
  send();
}

void Beacon::stop() {
  stopped_ = true;
  if (timer_) timer_->cancel();
}

void Beacon::send() {
  if (stopped_) return;
  const std::string datagram = "GMRB" + describe_().SerializeAsString();
  boost::system::error_code ec;
  socket_->send_to(net::buffer(datagram), group_, 0, ec);
  if (ec && !send_failed_) spdlog::warn("discovery beacon not sent (said once): {}", ec.message());
  if (ec) send_failed_ = true;
  timer_->expires_after(cfg_.discovery_interval);
  timer_->async_wait([this](const boost::system::error_code& e) {
    if (!e) send();
  });
}

}  // namespace gmr::server
