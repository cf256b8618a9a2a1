// A TCP connection that speaks TLS or not: the server's connections and the
// client use it alike. It lives apart from gmr::wire (proto/wire), which has
// no Asio: this header is the protocol's transport over Asio, shared by the
// two programs that use Asio. Reads and writes go through the TLS stream when there
// is one, straight to the socket otherwise; the rest of the code does not
// care which. Header-only; users link Boost.System and OpenSSL (OpenSSL::SSL).
#pragma once

#include <utility>  // std::exchange, which boost/asio/awaitable.hpp uses without including

#include <boost/asio.hpp>
#include <boost/asio/ssl.hpp>
#include <variant>

namespace gmr::asio {

class TlsSocket {
 public:
  using Tcp = boost::asio::ip::tcp::socket;
  using Tls = boost::asio::ssl::stream<Tcp>;

  explicit TlsSocket(boost::asio::io_context& io) : s_(std::in_place_type<Tcp>, io) {}
  // On an executor (a strand: handlers of one connection never run at once).
  explicit TlsSocket(const boost::asio::any_io_executor& executor) : s_(std::in_place_type<Tcp>, executor) {}
  explicit TlsSocket(Tcp socket) : s_(std::in_place_type<Tcp>, std::move(socket)) {}

  // From here on the connection speaks TLS (call before any byte is read or
  // written; the handshake comes next).
  void use_tls(boost::asio::ssl::context& context) {
    Tcp tcp = std::move(std::get<Tcp>(s_));
    s_.emplace<Tls>(std::move(tcp), context);
  }
  bool tls() const { return std::holds_alternative<Tls>(s_); }
  Tls& tls_stream() { return std::get<Tls>(s_); }
  Tcp& tcp() { return tls() ? std::get<Tls>(s_).next_layer() : std::get<Tcp>(s_); }

  template <class Buffers, class Handler>
  void async_read(const Buffers& buffers, Handler&& handler) {
    std::visit([&](auto& s) { boost::asio::async_read(s, buffers, std::forward<Handler>(handler)); }, s_);
  }
  template <class Buffers, class Handler>
  void async_read_some(const Buffers& buffers, Handler&& handler) {
    std::visit([&](auto& s) { s.async_read_some(buffers, std::forward<Handler>(handler)); }, s_);
  }
  template <class Buffers, class Handler>
  void async_write(const Buffers& buffers, Handler&& handler) {
    std::visit([&](auto& s) { boost::asio::async_write(s, buffers, std::forward<Handler>(handler)); }, s_);
  }

  // The peer went away: end of file, or a TLS peer that closed its socket
  // without a close_notify (what a killed process or a plain close does).
  static bool peer_closed(const boost::system::error_code& ec) {
    return ec == boost::asio::error::eof || ec == boost::asio::ssl::error::stream_truncated;
  }

 private:
  std::variant<Tcp, Tls> s_;
};

}  // namespace gmr::asio
