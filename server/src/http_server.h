// HttpListener: gmr-server's HTTP port (docs/viewer.md, docs/monitoring.md).
// Boost.Beast, on the server's I/O thread:
//
//   GET /                 the viewer (index.html, viewer.js, viewer.css from config.web_root)
//   GET /three/...        Debian's three.js (config.three_dir), which the viewer imports
//   GET /ws  (Upgrade)    a WebSocket client connection: WsConnection + RequestHandler,
//                         under the same admission and limits as a TCP client
//   GET /metrics          Prometheus text format (Metrics)
//   GET /healthz          200 while the I/O thread answers
//   GET /readyz           200 once the library has loaded, 503 before and while stopping
//
// Every session is bounded: 8 KiB of headers, no request body, one request
// at a time, config.http_timeout to send it, config.max_http_sessions open.
#pragma once

#include <cstdint>
#include <map>
#include <memory>

#include "gmr/server/server.h"
#include "net.h"

namespace gmr::server {

class HttpSession;

class HttpListener {
 public:
  explicit HttpListener(Server::Impl& server);
  // Binds and listens. Throws std::runtime_error naming the address when it cannot.
  void open(const net::ip::address& address, std::uint16_t port);
  // Starts accepting (nothing when open() was not called).
  void start();
  // Stops accepting and closes every HTTP session (WebSockets are client
  // connections: the server closes those).
  void close();
  std::uint16_t port() const { return port_; }

 private:
  friend class HttpSession;
  void accept();

  Server::Impl& server_;
  tcp::acceptor acceptor_;
  std::uint16_t port_ = 0;
  bool closed_ = false;
  std::uint64_t next_session_ = 1;
  std::map<std::uint64_t, std::weak_ptr<HttpSession>> sessions_;
};

}  // namespace gmr::server
