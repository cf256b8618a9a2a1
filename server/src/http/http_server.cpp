#include "http/http_server.h"

#include <spdlog/spdlog.h>

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <filesystem>
#include <optional>
#include <string_view>

#include "http/http_rules.h"
#include "transport/ws_connection.h"

namespace gmr::server {

namespace {

constexpr std::size_t kHeaderLimit = 8 * 1024;

using Request = http::request<http::string_body>;

}  // namespace

class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(HttpListener& listener, tcp::socket socket, std::uint64_t id, std::string address)
      : listener_(listener),
        server_(listener.services_),
        stream_(std::move(socket)),
        id_(id),
        address_(std::move(address)),
        group_(address_group(address_)) {}

  const std::string& group() const { return group_; }
  // Still waiting for a request head (not answering, not upgrading).
  bool waiting() const { return waiting_; }
  // Closed to make room for a newer connection (it was waiting for a request).
  void evict() {
    waiting_ = false;
    close();
    end();
  }

  // `refusal`: why it is turned away (one answer, then the connection closes).
  void start(const std::string& refusal) {
    if (!refusal.empty()) {
      respond(text_response(http::status::service_unavailable, 11, false, refusal + "; try again\n"));
      return;
    }
    read();
  }

  void close() {
    boost::system::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_both, ignored);
    stream_.close();
  }

 private:
  void read() {
    parser_.emplace();
    parser_->header_limit(kHeaderLimit);
    parser_->body_limit(0);  // GET and HEAD only: no body
    // The whole request head within the head deadline, however slowly it
    // trickles in (a byte at a time would otherwise hold the session).
    stream_.expires_after(server_.cfg.http_head_timeout);
    waiting_ = true;
    http::async_read(
        stream_, buffer_, *parser_,
        [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) { self->on_read(ec); });
  }

  void on_read(const boost::system::error_code& ec) {
    waiting_ = false;
    if (ec) {
      if (ec == http::error::end_of_stream || ec == beast::error::timeout || ec == net::error::operation_aborted ||
          ec == net::error::connection_reset || listener_.closed_) {
        end();
        return;
      }
      // A request that does not parse, or passes a bound: say which, then close.
      const http::status status = ec == http::error::header_limit ? http::status::request_header_fields_too_large
                                  : ec == http::error::body_limit ? http::status::payload_too_large
                                                                  : http::status::bad_request;
      respond(text_response(status, 11, false, "bad HTTP request: " + ec.message() + "\n"));
      return;
    }
    Request req = parser_->release();
    request_is_head_ = req.method() == http::verb::head;
    if (websocket::is_upgrade(req) && req.target() == "/ws") {
      upgrade(std::move(req));
      return;
    }
    if (auto res = route(req)) {
      respond(std::move(*res));
    } else {
      serve_file(req);
    }
  }

  http::response<http::string_body> text_response(http::status status, unsigned version, bool keep_alive,
                                                  std::string body,
                                                  std::string_view type = "text/plain; charset=utf-8") const {
    http::response<http::string_body> res{status, version};
    res.set(http::field::server, "gmr-server");
    res.set(http::field::content_type, beast::string_view(type.data(), type.size()));
    res.set(http::field::cache_control, "no-store");
    res.keep_alive(keep_alive);
    res.body() = std::move(body);
    res.prepare_payload();
    return res;
  }

  // The answer to a plain (not upgrading) request; nullopt: a file (serve_file).
  std::optional<http::response<http::string_body>> route(const Request& req) {
    const unsigned v = req.version();
    const bool keep = req.keep_alive();
    if (req.method() != http::verb::get && req.method() != http::verb::head) {
      auto res = text_response(http::status::method_not_allowed, v, keep, "only GET and HEAD\n");
      res.set(http::field::allow, "GET, HEAD");
      return res;
    }
    std::string_view target(req.target().data(), req.target().size());
    if (const auto q = target.find('?'); q != std::string_view::npos) target = target.substr(0, q);
    if (target == "/healthz") return text_response(http::status::ok, v, keep, "ok\n");
    if (target == "/readyz") {
      const auto status = server_.status();
      if (status.state == HttpServices::State::kStopping) {
        return text_response(http::status::service_unavailable, v, keep, "stopping\n");
      }
      if (status.state == HttpServices::State::kLoading) {
        return text_response(http::status::service_unavailable, v, keep, "loading the library\n");
      }
      return text_response(http::status::ok, v, keep, "ready: " + std::to_string(status.motions) + " motions\n");
    }
    if (target == "/metrics") {
      if (auto why = host_refused(req, server_.cfg))
        return text_response(http::status::forbidden, v, false, *why + "\n");
      return text_response(http::status::ok, v, keep, server_.metrics_text(),
                           "text/plain; version=0.0.4; charset=utf-8");
    }
    if (target == "/ws") {
      auto res = text_response(http::status::upgrade_required, v, keep,
                               std::string("/ws is a WebSocket: ask for the subprotocol ") + kWsBinaryProtocol +
                                   " or " + kWsJsonProtocol + " (docs/protocol.md)\n");
      res.set(http::field::upgrade, "websocket");
      return res;
    }
    return std::nullopt;
  }

  void respond(http::response<http::string_body> res) {
    if (request_is_head_) res.body().clear();  // the headers keep the length GET would have
    send(std::make_shared<http::response<http::string_body>>(std::move(res)));
  }

  template <class Body>
  void send(std::shared_ptr<http::response<Body>> res) {
    server_.metrics.http_response(res->result_int());
    stream_.expires_after(server_.cfg.http_timeout);
    const bool close_after = !res->keep_alive();
    http::async_write(stream_, *res,
                      [self = shared_from_this(), res, close_after](const boost::system::error_code& ec, std::size_t) {
                        if (ec || close_after || self->listener_.closed_) {
                          self->close();
                          self->end();
                          return;
                        }
                        self->read();
                      });
  }

  void serve_file(const Request& req) {
    const unsigned v = req.version();
    const bool keep = req.keep_alive();
    std::string_view target(req.target().data(), req.target().size());
    if (const auto q = target.find('?'); q != std::string_view::npos) target = target.substr(0, q);
    std::filesystem::path root = server_.cfg.web_root;
    std::string_view rel = target.substr(target.empty() ? 0 : 1);
    if (target == "/") rel = "index.html";
    if (rel.rfind("three/", 0) == 0) {
      root = server_.cfg.three_dir;
      rel.remove_prefix(6);
    }
    const auto safe = safe_relative(rel);
    std::filesystem::path file;
    boost::system::error_code ec;
    http::file_body::value_type body;
    if (safe && !root.empty()) {
      file = root / *safe;
      std::error_code fs_ec;
      if (std::filesystem::is_regular_file(file, fs_ec)) body.open(file.c_str(), beast::file_mode::scan, ec);
    }
    if (!safe || root.empty() || !body.is_open()) {
      if (!safe) {
        respond(text_response(http::status::bad_request, v, keep, "bad path\n"));
      } else {
        respond(text_response(http::status::not_found, v, keep,
                              root.empty() ? "no web root configured (--web-root)\n" : "not found\n"));
      }
      return;
    }
    const auto size = body.size();
    auto res = std::make_shared<http::response<http::file_body>>(
        std::piecewise_construct, std::make_tuple(std::move(body)), std::make_tuple(http::status::ok, v));
    res->set(http::field::server, "gmr-server");
    const std::string_view type = content_type(file);
    res->set(http::field::content_type, beast::string_view(type.data(), type.size()));
    res->set(http::field::cache_control, "no-cache");
    res->content_length(size);
    res->keep_alive(keep);
    if (request_is_head_) {
      auto head = std::make_shared<http::response<http::empty_body>>(http::status::ok, v);
      head->base() = res->base();
      send(head);
      return;
    }
    send(res);
  }

  void upgrade(Request req) {
    const unsigned v = req.version();
    auto refuse = [&](http::status status, const std::string& why) {
      respond(text_response(status, v, false, why + "\n"));
    };
    const auto state = server_.status().state;
    if (state == HttpServices::State::kStopping) {
      return refuse(http::status::service_unavailable, "the server is stopping");
    }
    if (state == HttpServices::State::kLoading) {
      return refuse(http::status::service_unavailable, "the library is still loading; try again shortly (/readyz)");
    }
    if (auto why = host_refused(req, server_.cfg)) return refuse(http::status::forbidden, *why);
    if (!origin_allowed(req, server_.cfg)) {
      return refuse(http::status::forbidden, "a page from another origin may not use this server (--allow-origin)");
    }
    const auto format = WsConnection::format_of(req);
    if (!format) {
      return refuse(http::status::bad_request, std::string("no WebSocket subprotocol this server speaks: ask for ") +
                                                   kWsBinaryProtocol + " or " + kWsJsonProtocol);
    }
    if (std::string why = server_.admit(address_); !why.empty()) {
      return refuse(http::status::service_unavailable, "refused: " + why);
    }
    // The socket leaves this session for a client connection.
    end();
    server_.open_websocket(stream_.release_socket(), std::move(req), *format, address_);
  }

  // The session is over: the listener forgets it.
  void end() {
    if (ended_) return;
    ended_ = true;
    listener_.sessions_.erase(id_);
    if (auto n = listener_.per_address_.find(group_); n != listener_.per_address_.end() && --n->second == 0) {
      listener_.per_address_.erase(n);
    }
  }

  HttpListener& listener_;
  const HttpServices& server_;
  beast::tcp_stream stream_;
  std::uint64_t id_;
  std::string address_;
  std::string group_;  // address_group(address_): what the per-address limit counts
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  bool request_is_head_ = false;
  bool waiting_ = false;
  bool ended_ = false;
};

HttpListener::HttpListener(net::io_context& io, HttpServices services)
    : services_(std::move(services)), acceptor_(io) {}

void HttpListener::open(const net::ip::address& address, std::uint16_t port) {
  const tcp::endpoint ep(address, port);
  boost::system::error_code ec;
  acceptor_.open(ep.protocol(), ec);
  if (!ec) acceptor_.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) acceptor_.bind(ep, ec);
  if (!ec) acceptor_.listen(net::socket_base::max_listen_connections, ec);
  if (ec) {
    throw std::runtime_error("cannot bind HTTP " + address.to_string() + ":" + std::to_string(port) + ": " +
                             ec.message());
  }
  port_ = acceptor_.local_endpoint().port();
}

void HttpListener::start() {
  if (acceptor_.is_open()) accept();
}

void HttpListener::accept() {
  acceptor_.async_accept([this](const boost::system::error_code& ec, tcp::socket socket) {
    if (ec) {
      if (ec == net::error::operation_aborted || closed_) return;
      spdlog::warn("HTTP accept failed: {}", ec.message());
    } else if (!closed_) {
      boost::system::error_code peer_ec;
      const auto peer = socket.remote_endpoint(peer_ec);
      const std::uint64_t id = next_session_++;
      auto session = std::make_shared<HttpSession>(*this, std::move(socket), id,
                                                   peer_ec ? std::string("?") : peer.address().to_string());
      const auto& cfg = services_.cfg;
      std::string refusal;
      if (cfg.max_http_sessions_per_address != 0 &&
          per_address_[session->group()] >= cfg.max_http_sessions_per_address) {
        refusal = "too many HTTP connections from one address (--max-http-sessions-per-address)";
      } else if (sessions_.size() >= cfg.max_http_sessions && !make_room()) {
        refusal = "too many HTTP connections (--max-http-sessions)";
      }
      sessions_[id] = session;
      ++per_address_[session->group()];
      session->start(refusal);
    }
    if (!closed_) accept();
  });
}

bool HttpListener::make_room() {
  // The oldest session still waiting for a request gives way: a client that
  // sends its request at once (a health probe) always finds a place, however
  // many sockets sit silent.
  for (auto it = sessions_.begin(); it != sessions_.end(); ++it) {
    auto s = it->second.lock();
    if (s && s->waiting()) {
      ++evicted_;
      s->evict();  // erases it from sessions_
      return true;
    }
  }
  return false;
}

void HttpListener::close() {
  closed_ = true;
  boost::system::error_code ec;
  acceptor_.close(ec);
  auto open = sessions_;
  for (auto& [id, weak] : open) {
    if (auto s = weak.lock()) s->close();
  }
}

}  // namespace gmr::server
