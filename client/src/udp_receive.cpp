#include "client_impl.h"

namespace gmr::client {

void Client::Impl::read_udp() {
  udp_socket.async_receive_from(net::buffer(udp_buffer), udp_sender,
                                [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
                                  if (ec == net::error::operation_aborted || !self->open) return;
                                  // Only datagrams from the server's address count.
                                  if (!ec && self->udp_sender == self->server_udp) {
                                    const std::string_view d(self->udp_buffer.data(), n);
                                    if (auto cookie = wire::parse_challenge_datagram(d)) {
                                      // The server asks this address to prove it registered: echo.
                                      wire::UdpToken token;
                                      std::memcpy(token.data(), self->hello.udp_token.data(), token.size());
                                      const std::string confirm = wire::make_confirm_datagram(token, *cookie);
                                      boost::system::error_code send_ec;
                                      self->udp_socket.send_to(net::buffer(confirm), self->server_udp, 0, send_ec);
                                    } else if (auto msg = self->reassembler.add(d)) {
                                      self->take_message(*msg, true);
                                    }
                                    std::lock_guard lock(self->mutex);
                                    self->counters.udp_incomplete_dropped = self->reassembler.dropped();
                                    self->counters.udp_malformed = self->reassembler.malformed();
                                  }
                                  self->read_udp();
                                });
}

Status Client::Impl::join_multicast(const std::string& group) {
  // From the server: checked, never trusted to parse (a throw here would
  // leave the strand).
  const auto colon = group.rfind(':');
  boost::system::error_code ec;
  const auto address = net::ip::make_address_v4(group.substr(0, colon == std::string::npos ? 0 : colon), ec);
  unsigned port = 0;
  const char* digits = group.data() + (colon == std::string::npos ? group.size() : colon + 1);
  const auto parsed = std::from_chars(digits, group.data() + group.size(), port);
  if (ec || colon == std::string::npos || !address.is_multicast() || parsed.ec != std::errc() ||
      parsed.ptr != group.data() + group.size() || port == 0 || port > 65535) {
    return make_error("the server named a bad multicast group '" + group.substr(0, 64) + "'");
  }
  if (multicast_socket) return Ok{};  // one group per server
  if (!open) return make_error("not connected: the connection closed before the multicast join");
  const auto local = socket.tcp().local_endpoint(ec).address();
  udp::socket s(strand);
  s.open(udp::v4(), ec);
  if (!ec) s.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) s.bind(udp::endpoint(net::ip::address_v4::any(), static_cast<std::uint16_t>(port)), ec);
  if (!ec) s.set_option(net::socket_base::receive_buffer_size(4 << 20), ec);
  if (!ec) {
    s.set_option(local.is_v4() ? net::ip::multicast::join_group(address, local.to_v4())
                               : net::ip::multicast::join_group(address),
                 ec);
  }
  if (ec) return make_error("cannot join multicast " + group + ": " + ec.message());
  multicast_socket.emplace(std::move(s));
  read_multicast();
  return Ok{};
}

void Client::Impl::read_multicast() {
  multicast_socket->async_receive_from(
      net::buffer(multicast_buffer), multicast_sender,
      [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
        if (ec == net::error::operation_aborted || !self->open) return;
        // Only the server's UDP socket sends the group's frames.
        if (!ec && self->multicast_sender == self->server_udp) {
          if (auto msg = self->multicast_reassembler.add(std::string_view(self->multicast_buffer.data(), n))) {
            pb::ServerMessage m;
            if (m.ParseFromString(*msg) && m.has_frame()) {
              std::vector<std::uint32_t> ids;
              {
                std::lock_guard lock(self->mutex);
                for (const auto& [id, sub] : self->subs) {
                  if (sub->multicast && sub->stream_id == m.frame().stream_id()) ids.push_back(id);
                }
              }
              for (const std::uint32_t id : ids) {
                m.mutable_frame()->set_subscription_id(id);
                self->on_message(m, true);
              }
            }
          }
        }
        self->read_multicast();
      });
}

}  // namespace gmr::client
