#include "udp_publisher.h"

#include <spdlog/spdlog.h>

#include <stdexcept>
#include <string>

#include "gmr/wire/udp.h"

namespace gmr::server {

UdpPublisher::UdpPublisher(net::io_context& io, std::size_t max_in_flight)
    : socket_(io), max_in_flight_(max_in_flight) {}

void UdpPublisher::open(const net::ip::address& address, std::uint16_t port) {
  const udp::endpoint ep(address, port);
  boost::system::error_code ec;
  socket_.open(ep.protocol(), ec);
  if (!ec) socket_.bind(ep, ec);
  if (ec) {
    throw std::runtime_error("cannot bind UDP " + address.to_string() + ":" + std::to_string(port) + ": " +
                             ec.message());
  }
  port_ = socket_.local_endpoint().port();
}

void UdpPublisher::start() { receive(); }

void UdpPublisher::close() {
  closed_ = true;
  boost::system::error_code ec;
  socket_.close(ec);
}

std::uint64_t UdpPublisher::add_session(OnRegister on_register) {
  std::uint64_t token = 0;
  do {
    token = rng_();
  } while (token == 0 || sessions_.count(token) != 0);
  sessions_.emplace(token, std::move(on_register));
  return token;
}

void UdpPublisher::remove_session(std::uint64_t token) { sessions_.erase(token); }

bool UdpPublisher::send(const std::shared_ptr<Registration>& to, std::string_view message) {
  if (closed_ || !to->endpoint) return false;
  auto datagrams = wire::fragment_message(to->next_message_id++, message);
  if (to->in_flight + datagrams.size() > max_in_flight_) return false;
  for (auto& d : datagrams) {
    auto held = std::make_shared<const std::string>(std::move(d));
    ++to->in_flight;
    socket_.async_send_to(net::buffer(*held), *to->endpoint,
                          [to, held](const boost::system::error_code&, std::size_t) { --to->in_flight; });
  }
  return true;
}

void UdpPublisher::receive() {
  socket_.async_receive_from(net::buffer(buffer_), sender_, [this](const boost::system::error_code& ec, std::size_t n) {
    if (ec == net::error::operation_aborted || closed_) return;
    if (!ec) {
      const auto token = wire::parse_register_datagram(std::string_view(buffer_.data(), n));
      const auto it = token ? sessions_.find(*token) : sessions_.end();
      if (it != sessions_.end()) {
        it->second(sender_);
      } else if (rejected_++ % 1000 == 0) {
        // Never answer: an unregistered address gets nothing from this server.
        spdlog::warn("ignoring a {}-byte UDP datagram from {}:{}: {} ({} so far)", n, sender_.address().to_string(),
                     sender_.port(), token ? "unknown session token" : "not a registration datagram", rejected_);
      }
    }
    receive();
  });
}

}  // namespace gmr::server
