#include "transport/connection.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <optional>

#include "gmr/wire/framing.h"
#include "transport/connection_log.h"

namespace gmr::server {

namespace {
// A request body is read in chunks that start at kFirstChunk and double as
// bytes arrive (at most kBodyChunk): the buffer is never more than about
// twice what arrived, whatever length the prefix announced.
constexpr std::size_t kFirstChunk = 4096;
}  // namespace

Connection::Connection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
                       BufferBudget* budget, net::ssl::context* tls, ConnectionPlacement placement)
    : QueuedOutbox(id, limits, budget),
      io_(io),
      control_(placement.control != nullptr ? placement.control : &io),
      lane_(placement.lane),
      threads_(placement.threads),
      socket_(std::move(socket)),
      watchdog_(io) {
  if (tls != nullptr) socket_.use_tls(*tls);
  secured_ = tls == nullptr;
  boost::system::error_code ec;
  auto ep = socket_.tcp().remote_endpoint(ec);
  peer_address_ = ec ? std::string("?") : ep.address().to_string();
  peer_ = ec ? std::string("?") : peer_address_ + ":" + std::to_string(ep.port());
}

template <class F>
void Connection::on_lane_do(F&& f) {
  if (on_lane()) {
    f();
  } else {
    net::post(io_, std::forward<F>(f));
  }
}

void Connection::read_more() {
  on_lane_do([self = shared_from_this()] {
    Lock lock(self->m_);
    self->read_next();
  });
}

void Connection::start(std::shared_ptr<Handler> handler, std::function<void(std::uint64_t)> on_closed) {
  {
    Lock lock(m_);
    handler_ = std::move(handler);
    on_closed_ = std::move(on_closed);
  }
  // The socket is the lane's: everything it does starts there.
  on_lane_do([self = shared_from_this()] {
    Lock lock(self->m_);
    if (self->stopped_) return;
    tune_socket(self->socket_.tcp(), self->limits_, self->id_);
    // A write is tried at once and must not block the lane (flush).
    boost::system::error_code ec;
    if (self->socket_.tcp().non_blocking(true, ec); ec) {
      self->stop("the socket cannot be made non-blocking: " + ec.message());
      return;
    }
    self->last_read_ = self->last_write_ = Clock::now();
    log_connection(spdlog::level::info, "conn {}: connected from {}{}", self->id_, self->peer_,
                   self->socket_.tls() ? " (TLS)" : "");
    self->arm_watchdog();
    if (!self->socket_.tls()) {
      self->read_next();
      return;
    }
    // The handshake counts against the Hello deadline (the watchdog's).
    self->socket_.tls_stream().async_handshake(net::ssl::stream_base::server,
                                               [self](const boost::system::error_code& e) {
                                                 Lock relock(self->m_);
                                                 if (self->stopped_) return;
                                                 if (e) {
                                                   self->stop("TLS handshake failed: " + e.message());
                                                   return;
                                                 }
                                                 self->secured_ = true;
                                                 self->last_read_ = Clock::now();
                                                 self->read_next();
                                                 self->flush();  // replies queued meanwhile
                                               });
  });
}

void Connection::stop(const std::string& reason) {
  std::shared_ptr<Handler> handler;
  std::function<void(std::uint64_t)> on_closed;
  {
    Lock lock(m_);
    if (stopped_) return;
    stopped_.store(true, std::memory_order_release);
    log_connection(spdlog::level::info, "conn {}: closed: {} (frames sent {}, dropped {})", id_, reason,
                   all_frames_sent(), all_frames_dropped());
    std::string().swap(body_);
    body_received_ = 0;
    drop_queued();
    // The handler goes with `tell`: a stopped connection holds none (its
    // subscriptions hold the connection, so that would be a cycle).
    handler = std::move(handler_);
    on_closed = std::move(on_closed_);
  }
  // The handler's and the server's part on the control loop, the socket's
  // on the lane (each at once when this is its thread).
  auto self = shared_from_this();
  auto tell = [self, handler = std::move(handler), on_closed = std::move(on_closed)] {
    if (handler) handler->on_stop();
    if (on_closed) on_closed(self->id_);
  };
  auto close = [self] {
    Lock lock(self->m_);
    boost::system::error_code ec;
    self->socket_.tcp().shutdown(tcp::socket::shutdown_both, ec);
    self->socket_.tcp().close(ec);
    self->watchdog_.cancel();
  };
  if (control_->get_executor().running_in_this_thread()) {
    tell();
  } else {
    net::post(*control_, std::move(tell));
  }
  on_lane_do(std::move(close));
}

void Connection::finish() {
  Lock lock(m_);
  close_after_flush_ = true;
  frames_.clear();
  account();
  request_flush();
}

void Connection::arm_watchdog() {
  watchdog_.expires_at(watchdog_next_tick(Clock::now()));
  watchdog_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    Lock lock(self->m_);
    if (ec || self->stopped_) return;
    if (std::string why = self->watchdog_tick(Clock::now()); !why.empty()) {
      self->stop(why);
      return;
    }
    self->arm_watchdog();
  });
}

void Connection::read_next() {
  if (stopped_) return;
  if (body_waiting_) {
    // A body announced while the budget could not take it: read it once
    // the budget can (the watchdog's tick and every write retry).
    if (!reserve_body()) {
      pause_reading(true);
      return;
    }
    if (auto request = start_body()) hand_over(std::move(*request), false);
    return;
  }
  // Back-pressure: a client that sends requests faster than it reads the
  // replies is not read until they drain; its replies never pile up beyond
  // the cap. While the server's buffers are over budget, nor is a connection
  // that holds more than its share of them; nor while a request is with the
  // Handler (or held there). Requests already read wait as well.
  if (!may_read()) {
    pause_reading();
    return;
  }
  if (in_end_ - in_begin_ >= wire::kLengthPrefixBytes) {
    if (auto request = take_buffered()) hand_over(std::move(*request), false);
    return;
  }
  // Part of a prefix stays, at the front; the rest of in_ takes what arrived
  // (Asio tries the read at once: when nothing has arrived, one recv says
  // EAGAIN and the read waits for the socket).
  std::copy(in_.begin() + static_cast<std::ptrdiff_t>(in_begin_), in_.begin() + static_cast<std::ptrdiff_t>(in_end_),
            in_.begin());
  in_end_ -= in_begin_;
  in_begin_ = 0;
  socket_.async_read_some(net::buffer(in_.data() + in_end_, in_.size() - in_end_),
                          [self = shared_from_this()](const boost::system::error_code& ec, std::size_t got) {
                            std::optional<std::string> request;
                            {
                              Lock lock(self->m_);
                              request = self->on_read(ec, got);
                            }
                            if (request) self->hand_over(std::move(*request));
                          });
}

std::optional<std::string> Connection::on_read(const boost::system::error_code& ec, std::size_t got) {
  if (stopped_) return std::nullopt;
  in_end_ += got;
  counters_.bytes_received += got;
  if (ec) {
    stop(asio::TlsSocket::peer_closed(ec) ? std::string("the client closed the connection")
                                          : "read failed: " + ec.message());
    return std::nullopt;
  }
  last_read_ = Clock::now();
  if (in_end_ - in_begin_ < wire::kLengthPrefixBytes) {
    read_next();  // the rest of the prefix
    return std::nullopt;
  }
  return take_buffered();
}

std::optional<std::string> Connection::take_buffered() {
  const std::span<const std::uint8_t, wire::kLengthPrefixBytes> prefix(in_.data() + in_begin_,
                                                                       wire::kLengthPrefixBytes);
  const std::uint32_t length = wire::read_length_prefix(prefix);
  in_begin_ += wire::kLengthPrefixBytes;
  if (auto s = wire::check_length(length, limits_.max_message_bytes); !s.ok()) {
    log_connection(spdlog::level::warn, "conn {}: bad length prefix: {}; closing", id_, s.error().message);
    stop("bad length prefix");
    return std::nullopt;
  }
  body_expected_ = length;
  body_received_ = 0;
  body_.clear();
  body_waiting_ = true;
  if (!reserve_body()) {
    pause_reading(true);  // the bytes wait in the kernel, not here
    return std::nullopt;
  }
  return start_body();
}

std::optional<std::string> Connection::start_body() {
  const std::size_t here = std::min(in_end_ - in_begin_, body_expected_);
  const auto from = in_.begin() + static_cast<std::ptrdiff_t>(in_begin_);
  in_begin_ += here;
  if (here == body_expected_) return finish_request(std::string(from, from + static_cast<std::ptrdiff_t>(here)));
  // The body is longer than what arrived with it: in_ is empty now, and
  // the rest is read into body_ itself.
  body_.assign(from, from + static_cast<std::ptrdiff_t>(here));
  body_received_ = here;
  in_begin_ = in_end_ = 0;
  read_body();
  return std::nullopt;
}

bool Connection::reserve_body() {
  if (budget_ != nullptr) {
    if (!budget_->try_reserve(body_expected_, accounted_)) return false;
    body_reserved_ = body_expected_;
  }
  body_waiting_ = false;
  return true;
}

Connection::~Connection() {
  if (budget_ != nullptr) budget_->unreserve(body_reserved_);
}

void Connection::read_body() {
  // The buffer grows as bytes arrive (a declared length allocates nothing;
  // reserve_body() counted it against the budget).
  const std::size_t chunk =
      std::min({kBodyChunk, std::max(kFirstChunk, body_received_), body_expected_ - body_received_});
  body_.resize(body_received_ + chunk);
  account();
  socket_.async_read(net::buffer(body_.data() + body_received_, chunk),
                     [self = shared_from_this()](const boost::system::error_code& e, std::size_t got) {
                       std::optional<std::string> request;
                       {
                         Lock lock(self->m_);
                         request = self->on_body(e, got);
                       }
                       if (request) self->hand_over(std::move(*request));
                     });
}

std::optional<std::string> Connection::on_body(const boost::system::error_code& ec, std::size_t got) {
  if (stopped_) return std::nullopt;
  body_received_ += got;
  counters_.bytes_received += got;
  if (ec) {
    log_connection(spdlog::level::warn, "conn {}: truncated message: {} of {} bytes announced; closing", id_,
                   body_received_, body_expected_);
    stop(asio::TlsSocket::peer_closed(ec) ? std::string("truncated message") : "read failed: " + ec.message());
    return std::nullopt;
  }
  last_read_ = Clock::now();
  if (body_received_ < body_expected_) {
    read_body();
    return std::nullopt;
  }
  std::string body = std::move(body_);
  body_ = std::string();  // a large request's buffer is not kept
  return finish_request(std::move(body));
}

std::string Connection::finish_request(std::string body) {
  // The request goes to the Handler; reading waits until it is answered.
  body_received_ = 0;
  if (budget_ != nullptr) budget_->unreserve(std::exchange(body_reserved_, 0));
  at_handler_ = true;
  account();
  read_next();  // pauses: a request is with the Handler
  return body;
}

void Connection::hand_over(std::string body, bool inline_ok) {
  // Without the lock: the Handler calls back into this connection, and must
  // not hold up its lane meanwhile.
  auto hand = [self = shared_from_this(), body = std::move(body)] {
    std::shared_ptr<Handler> handler;
    {
      Lock lock(self->m_);
      if (self->stopped_) return;
      handler = self->handler_;
    }
    handler->on_message(body);
    Lock lock(self->m_);
    self->handed_back();
  };
  if (control_ == &io_ && inline_ok) {
    hand();
  } else {
    net::post(*control_, std::move(hand));
  }
}

void Connection::handed_back() {
  at_handler_ = false;
  resume_reading();
}

}  // namespace gmr::server
