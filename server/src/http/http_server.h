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
//
// It knows the rest of the server only through HttpServices: the state
// /readyz reports, the /metrics text, and a factory for WebSocket clients.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "gmr/server/config.h"
#include "http/metrics.h"
#include "transport/net.h"
#include "transport/ws_connection.h"

namespace gmr::server {

class HttpSession;

struct HttpServices {
  enum class State { kLoading, kReady, kStopping };
  struct Status {
    State state = State::kLoading;
    std::size_t motions = 0;  // in the library
  };
  const ServerConfig& cfg;
  Metrics& metrics;
  std::function<Status()> status;
  std::function<std::string()> metrics_text;  // what /metrics answers
  // Why a WebSocket client from `address` is refused (empty: it may come).
  std::function<std::string(const std::string& address)> admit;
  // A WebSocket client admitted: its socket, upgrade request and format.
  std::function<void(tcp::socket, http::request<http::string_body>, WsConnection::Format, const std::string& address)>
      open_websocket;
};

class HttpListener {
 public:
  HttpListener(net::io_context& io, HttpServices services);
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
  // Closes the oldest session waiting for a request; false when none is.
  bool make_room();

  HttpServices services_;
  tcp::acceptor acceptor_;
  std::uint16_t port_ = 0;
  bool closed_ = false;
  std::uint64_t next_session_ = 1;
  // Open sessions by id (ids grow: the first is the oldest), and how many
  // each address (address_group) holds.
  std::map<std::uint64_t, std::weak_ptr<HttpSession>> sessions_;
  std::map<std::string, std::size_t> per_address_;
  std::uint64_t evicted_ = 0;
};

}  // namespace gmr::server
