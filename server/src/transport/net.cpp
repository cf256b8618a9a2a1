#include "transport/net.h"

#include "transport/connection_log.h"

#include <algorithm>
#include <memory>

#include "gmr/wire/convert.h"
#include "gmr/wire/framing.h"

namespace gmr::server {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string multicast_unreachable(const net::ip::address& bound, const net::ip::address_v4& group) {
  if (!bound.is_loopback()) return {};
  // The source address the kernel picks for the group says where it routes it.
  net::io_context io;
  udp::socket probe(io);
  boost::system::error_code ec;
  probe.open(udp::v4(), ec);
  if (!ec) probe.connect(udp::endpoint(group, 9), ec);
  const auto source = ec ? net::ip::address() : probe.local_endpoint(ec).address();
  // A source on loopback, or none (a route on `lo` without one, as in a
  // network namespace): the group is routed on loopback, local listeners hear it.
  if (!ec && (source.is_loopback() || source.is_unspecified())) return {};
  return "bound to " + bound.to_string() + ", it goes out on the loopback interface, but this machine routes " +
         group.to_string() +
         (ec ? std::string(" nowhere (") + ec.message() + ")" : " through " + source.to_string() + "'s interface") +
         ", where listeners join, so nobody hears it: give --bind a LAN address of this host, or 0.0.0.0 "
         "(docs/live.md, \"What to bind\")";
}

std::string printable(std::string_view text, std::size_t max) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out = "\"";
  const std::size_t shown = std::min(text.size(), max);
  for (std::size_t i = 0; i < shown; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\n') {
      out += "\\n";
    } else if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20 || c > 0x7e) {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    } else {
      out += static_cast<char>(c);
    }
  }
  out += '"';
  if (text.size() > shown) out += " (and " + std::to_string(text.size() - shown) + " more bytes)";
  return out;
}

std::string address_group(const std::string& address) {
  boost::system::error_code ec;
  const auto a = net::ip::make_address(address, ec);
  if (ec || a.is_v4()) return address;
  auto v6 = a.to_v6();
  if (v6.is_v4_mapped()) return net::ip::make_address_v4(net::ip::v4_mapped, v6).to_string();
  auto bytes = v6.to_bytes();
  std::fill(bytes.begin() + 8, bytes.end(), 0);
  return net::ip::address_v6(bytes).to_string() + "/64";
}

ConnectionLog& connection_log() {
  static ConnectionLog log;
  return log;
}

bool LogLimiter::allow(std::uint64_t& suppressed) {
  const auto now = Clock::now();
  if (now - window_start_ >= period_) {
    window_start_ = now;
    in_window_ = 0;
  }
  if (in_window_ >= burst_) {
    ++suppressed_;
    return false;
  }
  ++in_window_;
  suppressed = suppressed_;
  suppressed_ = 0;
  return true;
}

pb::ServerMessage error_message(std::uint64_t request_id, pb::ErrorCode code, std::string text) {
  pb::ServerMessage m;
  m.set_request_id(request_id);
  m.mutable_error()->set_code(code);
  m.mutable_error()->set_message(std::move(text));
  return m;
}

void refuse_socket(tcp::socket socket, const pb::ServerMessage& refusal) {
  auto bytes = std::make_shared<std::string>(wire::frame_message(refusal).value());
  auto sock = std::make_shared<tcp::socket>(std::move(socket));
  net::async_write(*sock, net::buffer(*bytes), [sock, bytes](const boost::system::error_code&, std::size_t) {
    boost::system::error_code ignored;
    sock->shutdown(tcp::socket::shutdown_both, ignored);
    sock->close(ignored);
  });
}

}  // namespace gmr::server
