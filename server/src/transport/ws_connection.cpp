#include "transport/ws_connection.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "gmr/wire/frames.h"
#include "gmr/wire/framing.h"
#include "transport/connection_log.h"

namespace gmr::server {

namespace {
// How long a closing handshake may take before the socket is simply closed.
constexpr auto kCloseGrace = std::chrono::seconds(2);
// A read buffer grown past this by a large request is not kept.
constexpr std::size_t kKeptReadBuffer = 256 * 1024;

// Replies converted on the conversion thread (WsConnection::converted_aside).
std::atomic<std::uint64_t> g_converted_aside{0};

}  // namespace

std::uint64_t WsConnection::converted_aside() { return g_converted_aside.load(std::memory_order_relaxed); }

WsConnection::WsConnection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
                           BufferBudget* budget, std::optional<net::any_io_executor> convert)
    : QueuedOutbox(id, limits, budget), ws_(std::move(socket)), watchdog_(io), convert_(std::move(convert)) {
  boost::system::error_code ec;
  const auto ep = beast::get_lowest_layer(ws_).socket().remote_endpoint(ec);
  peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
}

std::optional<WsConnection::Format> WsConnection::format_of(const http::request<http::string_body>& upgrade) {
  const auto offered = upgrade[http::field::sec_websocket_protocol];
  if (offered.empty()) return Format::kBinary;
  // A comma-separated list, in the client's order of preference.
  std::string_view rest(offered.data(), offered.size());
  while (!rest.empty()) {
    const auto comma = rest.find(',');
    std::string_view name = rest.substr(0, comma);
    rest = comma == std::string_view::npos ? std::string_view() : rest.substr(comma + 1);
    while (!name.empty() && (name.front() == ' ' || name.front() == '\t')) name.remove_prefix(1);
    while (!name.empty() && (name.back() == ' ' || name.back() == '\t')) name.remove_suffix(1);
    if (name == kWsBinaryProtocol) return Format::kBinary;
    if (name == kWsJsonProtocol) return Format::kJson;
  }
  return std::nullopt;
}

void WsConnection::start(http::request<http::string_body> upgrade, Format format,
                         std::shared_ptr<Connection::Handler> handler, std::function<void(std::uint64_t)> on_closed) {
  handler_ = std::move(handler);
  on_closed_ = std::move(on_closed);
  format_ = format;
  tune_socket(beast::get_lowest_layer(ws_).socket(), limits_, id_);
  beast::get_lowest_layer(ws_).expires_never();  // the watchdog keeps time
  websocket::stream_base::timeout timeouts{};
  timeouts.handshake_timeout =
      limits_.handshake_timeout.count() > 0
          ? std::chrono::duration_cast<std::chrono::steady_clock::duration>(limits_.handshake_timeout)
          : std::chrono::steady_clock::duration(std::chrono::seconds(5));
  timeouts.idle_timeout = websocket::stream_base::none();
  timeouts.keep_alive_pings = false;
  ws_.set_option(timeouts);
  ws_.read_message_max(limits_.max_message_bytes);
  const bool named = !upgrade[http::field::sec_websocket_protocol].empty();
  const char* protocol = format == Format::kJson ? kWsJsonProtocol : kWsBinaryProtocol;
  ws_.set_option(websocket::stream_base::decorator([named, protocol](websocket::response_type& res) {
    res.set(http::field::server, "gmr-server");
    if (named) res.set(http::field::sec_websocket_protocol, protocol);
  }));
  last_read_ = last_write_ = Clock::now();
  log_connection(spdlog::level::info, "conn {}: WebSocket ({}) from {}", id_, protocol, peer_);
  arm_watchdog();
  // The request must outlive the accept: it is kept in the handler.
  auto request = std::make_shared<http::request<http::string_body>>(std::move(upgrade));
  ws_.async_accept(*request, [self = shared_from_this(), request](const boost::system::error_code& ec) {
    if (self->stopped_) return;
    if (ec) {
      self->stop("WebSocket handshake failed: " + ec.message());
      return;
    }
    self->open_ = true;
    self->last_read_ = Clock::now();
    self->read();
    self->flush();
  });
}

void WsConnection::read() {
  if (stopped_ || reading_) return;
  if (!may_read()) {  // back-pressure, as over TCP
    pause_reading();
    return;
  }
  reading_ = true;
  // A message is read a piece at a time and counted against the buffer
  // budget as it arrives (reading_bytes): a connection holding more than
  // its share of a budget that is over is not read until it drains, so
  // messages in flight cannot take the server past --max-buffered-bytes.
  ws_.async_read_some(in_, kReadPiece, [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
    self->on_read(ec, n);
  });
}

void WsConnection::on_read(const boost::system::error_code& ec, std::size_t bytes) {
  reading_ = false;
  if (stopped_) return;
  if (ec) {
    if (ec == websocket::error::message_too_big) {
      log_connection(spdlog::level::warn, "conn {}: a WebSocket message longer than {} bytes; closing", id_,
                     limits_.max_message_bytes);
      stop("message too large");
    } else if (ec == websocket::error::closed || ec == net::error::eof) {
      stop("the client closed the connection");
    } else {
      stop("read failed: " + ec.message());
    }
    return;
  }
  counters_.bytes_received += bytes;
  last_read_ = Clock::now();
  if (!ws_.is_message_done()) {
    account();
    read();
    return;
  }
  std::string body = beast::buffers_to_string(in_.data());
  in_.consume(in_.size());
  if (in_.capacity() > kKeptReadBuffer) in_ = beast::flat_buffer();
  if (ws_.got_text()) {
    // protobuf's JSON mapping of a ClientMessage: parsed here, so the
    // handler sees the same bytes a TCP client would send.
    auto binary = client_message_from_json(body);
    if (!binary.ok()) {
      send(wire::frame_message(error_message(0, pb::ERROR_CODE_BAD_REQUEST,
                                             "cannot parse the text message as the JSON of a "
                                             "gmr.stream.v1.ClientMessage: " +
                                                 binary.error().message))
               .value());
      read();
      return;
    }
    body = std::move(binary).value();
  }
  handler_->on_message(body);
  account();
  read();
}

void WsConnection::finish() {
  Lock lock(m_);
  close_after_flush_ = true;
  frames_.clear();
  account();
  flush();
}

std::string WsConnection::to_client(std::string_view framed) const {
  const std::string_view body = framed.substr(wire::kLengthPrefixBytes);
  if (format_ == Format::kBinary) return std::string(body);
  auto json = server_message_to_json(body);
  if (!json.ok()) {
    spdlog::error("conn {}: {}", id_, json.error().message);
    return {};
  }
  return std::move(json).value();
}

void WsConnection::flush() {
  if (writing_ || stopped_ || !open_) return;
  if (!replies_.empty()) {
    auto reply = std::move(replies_.front());
    reply_bytes_ -= reply->size();
    replies_.pop_front();
    if (format_ == Format::kJson && convert_ && reply->size() >= kConvertAsideFrom) {
      // The JSON is made on the conversion thread; meanwhile the write slot
      // is held (nothing overtakes this reply) and its bytes are counted.
      writing_ = true;
      write_started_ = Clock::now();  // the watchdog and congestion checks time the conversion as a write
      in_flight_bytes_ = reply->size();
      account();
      net::post(*convert_, [self = shared_from_this(), reply = std::move(reply)] {
        std::string json = self->to_client(*reply);  // touches format_ and id_ only, which do not change
        g_converted_aside.fetch_add(1, std::memory_order_relaxed);
        net::post(self->ws_.get_executor(), [self, json = std::move(json)]() mutable {
          self->writing_ = false;
          self->in_flight_bytes_ = 0;
          if (self->stopped_) {
            self->account();
            self->close_socket();
            return;
          }
          self->write(std::move(json), false);
        });
      });
      return;
    }
    write(to_client(*reply), false);
    return;
  }
  // One frame per message, the subscriptions taking turns.
  if (auto f = frames_.pop_next(next_key_, Clock::now(), counters_)) {
    oldest_frame_in_flight_ = f->pushed_at;
    write(to_client(stamped(*f, now_ns(), Clock::now())), true);
    return;
  }
  account();
  if (close_after_flush_) stop("closed by the server");
}

void WsConnection::write(std::string message, bool frame) {
  if (message.empty()) {  // could not be converted (logged): the next one
    account();
    flush();
    return;
  }
  out_ = std::move(message);
  in_flight_bytes_ = out_.size();
  writing_ = true;
  writing_frames_ = frame;
  write_started_ = Clock::now();
  account();
  ws_.text(format_ == Format::kJson);
  ws_.async_write(net::buffer(out_), [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
    self->writing_ = false;
    self->in_flight_bytes_ = 0;
    if (self->out_.capacity() > kKeptReadBuffer) std::string().swap(self->out_);
    self->account();
    if (ec) {
      if (!self->stopped_) self->stop("write failed: " + ec.message());
      self->close_socket();
      return;
    }
    self->wrote(n);
    if (self->stopped_) {
      self->close_socket();
      return;
    }
    self->resume_reading();
    self->flush();
  });
}

void WsConnection::stop(const std::string& reason) {
  if (stopped_) return;
  stopped_.store(true, std::memory_order_release);
  log_connection(spdlog::level::info, "conn {}: closed: {} (frames sent {}, dropped {})", id_, reason,
                 all_frames_sent(), all_frames_dropped());
  if (handler_) handler_->on_stop();
  drop_queued();
  if (on_closed_) on_closed_(id_);
  // A write in flight finishes first (one write at a time); its completion closes.
  if (!writing_) close_socket();
}

void WsConnection::close_socket() {
  if (socket_closed_) return;
  socket_closed_ = true;
  watchdog_.cancel();
  if (!open_) {
    boost::system::error_code ignored;
    beast::get_lowest_layer(ws_).socket().shutdown(tcp::socket::shutdown_both, ignored);
    beast::get_lowest_layer(ws_).close();
    return;
  }
  // The closing handshake, bounded: a client that does not answer is cut off.
  watchdog_.expires_after(kCloseGrace);
  watchdog_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    if (!ec) beast::get_lowest_layer(self->ws_).close();
  });
  ws_.async_close(websocket::close_code::normal, [self = shared_from_this()](const boost::system::error_code&) {
    self->watchdog_.cancel();
    beast::get_lowest_layer(self->ws_).close();
  });
}

void WsConnection::arm_watchdog() {
  watchdog_.expires_at(watchdog_next_tick(Clock::now()));
  watchdog_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    if (ec || self->stopped_) return;
    if (std::string why = self->watchdog_tick(Clock::now()); !why.empty()) {
      self->stop(why);
      return;
    }
    self->arm_watchdog();
  });
}

}  // namespace gmr::server
