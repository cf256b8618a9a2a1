#include "transport/connection.h"

#include <spdlog/spdlog.h>

#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <optional>

#include "gmr/wire/frames.h"
#include "gmr/wire/framing.h"
#include "prometheus/histogram.h"

namespace gmr::server {

namespace {
// A request body is read in chunks that start at kFirstChunk and double as
// bytes arrive (at most kBodyChunk): the buffer is never more than about
// twice what arrived, whatever length the prefix announced.
constexpr std::size_t kFirstChunk = 4096;
constexpr std::size_t kBodyChunk = 256 * 1024;
}  // namespace

void tune_socket(tcp::socket& socket, const ConnectionLimits& limits, std::uint64_t id) {
  boost::system::error_code ec;
  socket.set_option(tcp::no_delay(true), ec);
  if (limits.socket_send_buffer > 0) {
    socket.set_option(net::socket_base::send_buffer_size(limits.socket_send_buffer), ec);
  }
  if (limits.socket_unsent_bytes > 0) {
    // Bytes the kernel may hold that it has not sent: past them a write
    // waits, so frames wait in the connection's queue, where latest-wins and
    // the staleness bound apply, rather than in the kernel, where they would
    // reach a client that stalled seconds late (docs/protocol.md, "Staleness").
    const int lowat = limits.socket_unsent_bytes;
    if (::setsockopt(socket.native_handle(), IPPROTO_TCP, TCP_NOTSENT_LOWAT, &lowat, sizeof lowat) != 0) {
      spdlog::debug("conn {}: TCP_NOTSENT_LOWAT: {}", id, std::strerror(errno));
    }
  }
}

Connection::Connection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
                       BufferBudget* budget, net::ssl::context* tls, ConnectionPlacement placement)
    : io_(io),
      control_(placement.control != nullptr ? placement.control : &io),
      lane_(placement.lane),
      threads_(placement.threads),
      socket_(std::move(socket)),
      id_(id),
      limits_(limits),
      budget_(budget),
      frames_(limits.frames_per_key, limits.max_frame_bytes),
      watchdog_(io) {
  if (tls != nullptr) socket_.use_tls(*tls);
  secured_ = tls == nullptr;
  boost::system::error_code ec;
  auto ep = socket_.tcp().remote_endpoint(ec);
  peer_address_ = ec ? std::string("?") : ep.address().to_string();
  peer_ = ec ? std::string("?") : peer_address_ + ":" + std::to_string(ep.port());
}

Connection::~Connection() {
  if (budget_ != nullptr) budget_->release(accounted_);
}

template <class F>
void Connection::on_lane_do(F&& f) {
  if (on_lane()) {
    f();
  } else {
    net::post(io_, std::forward<F>(f));
  }
}

void Connection::account() {
  if (budget_ != nullptr) budget_->settle(accounted_, queued_bytes() + body_.size());
}

bool Connection::stopped() const { return stopped_.load(std::memory_order_acquire); }

bool Connection::closing() const {
  Lock lock(m_);
  return stopped_ || close_after_flush_;
}

void Connection::established() {
  Lock lock(m_);
  established_ = true;
}

void Connection::hold_reading(bool hold) {
  Lock lock(m_);
  reads_held_ = hold;
  if (!hold) resume_reading();
}

bool Connection::may_read() const {
  return !reads_held_ && !at_handler_ && reply_bytes_ + in_flight_bytes_ <= limits_.max_reply_queue_bytes &&
         (budget_ == nullptr || budget_->allows_reading(accounted_));
}

void Connection::resume_reading() {
  if (stopped_ || !read_paused_ || !may_read()) return;
  read_paused_ = false;
  on_lane_do([self = shared_from_this()] {
    Lock lock(self->m_);
    self->read_prefix();
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
    self->last_read_ = self->last_write_ = Clock::now();
    spdlog::info("conn {}: connected from {}{}", self->id_, self->peer_, self->socket_.tls() ? " (TLS)" : "");
    self->arm_watchdog();
    if (!self->socket_.tls()) {
      self->read_prefix();
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
                                                 self->read_prefix();
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
    spdlog::info("conn {}: closed: {} (frames sent {}, dropped {})", id_, reason, counters_.frames_sent,
                 counters_.frames_dropped);
    frames_.clear();
    replies_.clear();
    reply_bytes_ = 0;
    std::string().swap(body_);
    body_received_ = 0;
    account();
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

void Connection::close_after_reply() {
  Lock lock(m_);
  close_on_next_reply_ = true;
  frames_.clear();
  account();
}

void Connection::send(std::string framed) {
  Lock lock(m_);
  if (stopped_) return;
  reply_bytes_ += framed.size();
  replies_.push_back(std::make_shared<const std::string>(std::move(framed)));
  // Closing waits for this reply (and not for one another thread queues).
  if (std::exchange(close_on_next_reply_, false)) {
    close_after_flush_ = true;
    frames_.clear();
  }
  note_queue();
  account();
  request_flush();
}

bool Connection::push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body,
                            Clock::duration max_age) {
  Lock lock(m_);
  if (stopped_ || close_after_flush_) return true;
  // With no write in flight the frame goes out at once; otherwise it waits,
  // within this connection's bounds and the server's budget.
  const Clock::time_point now = Clock::now();
  const Clock::time_point stale_at = max_age > Clock::duration::zero() ? now + max_age : Clock::time_point::max();
  const bool kept_all = frames_.push(key, PendingFrame{std::move(head), std::move(body), stale_at, now}, writing_,
                                     budget_ != nullptr && budget_->over(), counters_);
  note_queue();
  account();
  request_flush();
  return kept_all;
}

bool Connection::congested(std::uint32_t key) const {
  Lock lock(m_);
  if (stopped_) return false;
  if (!writing_) {
    // Its I/O thread has not come round to the write it was handed: the
    // thread is behind (overloaded), and frames would only pile up.
    return flush_posted_ && frames_.waiting(key) && Clock::now() - flush_asked_ > limits_.congested_after;
  }
  if (budget_ != nullptr && budget_->over()) return true;
  if (!frames_.waiting(key)) return false;
  return Clock::now() - write_started_ > limits_.congested_after;
}

void Connection::discard_frames(std::uint32_t key) {
  Lock lock(m_);
  frames_.discard(key);
  account();
}

void Connection::send_frames_now(std::uint32_t key) {
  Lock lock(m_);
  const std::int64_t now = now_ns();
  for (auto& frame : frames_.take(key)) {
    wire::set_write_stamp(frame.head, now);
    auto bytes = std::make_shared<const std::string>(frame.head + *frame.body);
    reply_bytes_ += bytes->size();
    replies_.push_back(std::move(bytes));
    ++counters_.frames_sent;
  }
  account();
}

std::uint64_t Connection::end_frames(std::uint32_t key) {
  Lock lock(m_);
  const std::uint64_t stale = frames_.stale_dropped(key);
  send_frames_now(key);
  frames_.discard(key);
  account();
  return stale;
}

void Connection::count_udp_frame_sent() {
  Lock lock(m_);
  CountingOutbox::count_udp_frame_sent();
}
void Connection::count_udp_frame_dropped() {
  Lock lock(m_);
  CountingOutbox::count_udp_frame_dropped();
}
void Connection::count_frame_dropped(std::uint64_t n) {
  Lock lock(m_);
  CountingOutbox::count_frame_dropped(n);
}
void Connection::count_frame_skipped(std::uint64_t n) {
  Lock lock(m_);
  CountingOutbox::count_frame_skipped(n);
}

void Connection::note_queue() { counters_.max_queued_bytes = std::max(counters_.max_queued_bytes, queued_bytes()); }

ConnectionCounters Connection::counters() const {
  Lock lock(m_);
  ConnectionCounters c = counters_;
  c.queued_bytes = queued_bytes();
  return c;
}

void Connection::request_flush() {
  if (writing_ || stopped_) return;
  if (on_lane()) {
    flush();
    return;
  }
  // Once per wake of the lane: what else arrives meanwhile goes in the same
  // write. Only the control loop asks from off the lane.
  if (flush_posted_) return;
  flush_posted_ = true;
  flush_asked_ = Clock::now();
  auto self = shared_from_this();
  if (threads_ != nullptr) {
    threads_->defer(lane_, LaneTask{[](void* c) { static_cast<Connection*>(c)->deferred_flush(); }, this, self});
    return;
  }
  net::post(io_, [self] { self->deferred_flush(); });
}

void Connection::deferred_flush() {
  Lock lock(m_);
  flush_posted_ = false;
  flush();
}

void Connection::flush() {
  if (writing_ || stopped_ || !secured_) return;
  if (replies_.empty() && frames_.empty()) {
    if (close_after_flush_) stop("closed by the server");
    return;
  }
  // One gathered write: every waiting reply, then every waiting frame (its
  // own head, then the shared body).
  std::vector<net::const_buffer> buffers;
  hold_.clear();
  hold_heads_.clear();
  in_flight_bytes_ = 0;
  for (auto& r : replies_) {
    buffers.push_back(net::buffer(*r));
    in_flight_bytes_ += r->size();
    hold_.push_back(std::move(r));
  }
  replies_.clear();
  reply_bytes_ = 0;
  // Frames still within their subscriber's staleness bound, each its own
  // head then the shared body (hold_heads_ is reserved: buffers point into it).
  const std::size_t first_frame = hold_.size();
  hold_heads_.reserve(frames_.count());
  // Every frame of this write is stamped with the same time: now.
  const std::int64_t now = now_ns();
  frames_.drain(Clock::now(), counters_, [&](std::uint32_t, PendingFrame& f) {
    oldest_frame_in_flight_ = std::min(oldest_frame_in_flight_, f.pushed_at);
    wire::set_write_stamp(f.head, now);
    hold_heads_.push_back(std::move(f.head));
    in_flight_bytes_ += hold_heads_.back().size() + f.body->size();
    hold_.push_back(std::move(f.body));
    ++counters_.frames_sent;
  });
  for (std::size_t i = first_frame, head = 0; i < hold_.size(); ++i, ++head) {
    buffers.push_back(net::buffer(hold_heads_[head]));
    buffers.push_back(net::buffer(*hold_[i]));
  }
  writing_frames_ = !hold_heads_.empty();
  if (!writing_frames_) oldest_frame_in_flight_ = Clock::time_point::max();
  if (buffers.empty()) {  // every waiting frame was stale
    account();
    if (close_after_flush_) stop("closed by the server");
    return;
  }
  writing_ = true;
  write_started_ = Clock::now();
  if (socket_.tls()) {
    // TLS writes one buffer at a time: given in one piece, the bytes go out
    // in full records rather than one record (and one send) per buffer.
    tls_out_.clear();
    tls_out_.reserve(in_flight_bytes_);
    for (const auto& b : buffers) tls_out_.append(static_cast<const char*>(b.data()), b.size());
    buffers.assign(1, net::buffer(tls_out_));
    hold_.clear();  // the copy is what is in flight now
    hold_heads_.clear();
  }
  account();
  socket_.async_write(buffers, [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
    Lock lock(self->m_);
    self->writing_ = false;
    self->counters_.bytes_sent += n;
    self->hold_.clear();
    self->hold_heads_.clear();
    if (self->tls_out_.capacity() > kBodyChunk) std::string().swap(self->tls_out_);
    self->in_flight_bytes_ = 0;
    self->account();
    if (ec) {
      if (ec != net::error::operation_aborted) self->stop("write failed: " + ec.message());
      return;
    }
    self->last_write_ = Clock::now();
    if (self->writing_frames_) {
      self->last_frames_written_ = self->last_write_;
      if (self->frame_wait_ != nullptr) {
        self->frame_wait_->Observe(std::chrono::duration<double>(self->last_write_ - self->oldest_frame_in_flight_).count());
      }
      self->oldest_frame_in_flight_ = Clock::time_point::max();
    }
    if (self->read_paused_ && self->may_read()) {
      self->read_paused_ = false;
      self->read_prefix();
    }
    self->flush();
  });
}

std::chrono::milliseconds watchdog_period(const ConnectionLimits& l, bool established) {
  using std::chrono::milliseconds;
  auto shortest = std::min({l.heartbeat_interval, l.idle_timeout, l.write_timeout});
  if (!established && l.handshake_timeout.count() > 0) shortest = std::min(shortest, l.handshake_timeout);
  return std::max(milliseconds(10), shortest / 4);
}

std::string watchdog_verdict(const LinkTimes& t, const ConnectionLimits& lim, Clock::time_point now, std::uint64_t id) {
  if (!t.established && lim.handshake_timeout.count() > 0 && now - t.started > lim.handshake_timeout) {
    spdlog::warn("conn {}: no Hello within {} ms", id, lim.handshake_timeout.count());
    return "no Hello in time";
  }
  // A client that only listens to a subscription is not idle while its
  // frames are written: a dead one stops taking them, and the write timeout
  // below closes it. Heartbeats the server writes do not count.
  if (now - t.last_read > lim.idle_timeout && now - t.last_frames_written > lim.idle_timeout) {
    spdlog::warn("conn {}: idle for more than {} ms", id, lim.idle_timeout.count());
    return "idle timeout";
  }
  if (t.writing && now - t.write_started > lim.write_timeout) {
    spdlog::warn("conn {}: a write made no progress for {} ms: the client is not reading", id,
                 lim.write_timeout.count());
    return "write timeout";
  }
  return {};
}

void Connection::arm_watchdog() {
  watchdog_.expires_after(watchdog_period(limits_, established_));
  watchdog_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    Lock lock(self->m_);
    if (ec || self->stopped_) return;
    const auto now = Clock::now();
    // A client whose request the server is still on (its reads held for an
    // edit, or a body with the handler) waits for the server: not idle.
    if (self->reads_held_ || self->at_handler_) self->last_read_ = now;
    const LinkTimes times{self->established_, self->writing_,       self->started_,
                          self->last_read_,   self->write_started_, self->last_frames_written_};
    if (std::string why = watchdog_verdict(times, self->limits_, now, self->id_); !why.empty()) {
      self->stop(why);
      return;
    }
    // Reads paused for the server-wide budget resume once it allows.
    if (self->read_paused_ && self->may_read()) {
      self->read_paused_ = false;
      self->read_prefix();
    }
    // (Nothing is written into a TLS stream before its handshake.)
    if (self->secured_ && !self->writing_ && now - self->last_write_ > self->limits_.heartbeat_interval) {
      self->send(heartbeat_message());
      self->last_write_ = now;
    }
    self->arm_watchdog();
  });
}

std::string heartbeat_message() {
  pb::ServerMessage hb;
  hb.mutable_heartbeat()->set_client_time_ns(0);
  return wire::frame_message(hb).value();
}

void Connection::read_prefix() {
  if (stopped_) return;
  // Back-pressure: a client that sends requests faster than it reads the
  // replies is not read until they drain; its replies never pile up beyond
  // the cap. While the server's buffers are over budget, nor is a connection
  // that holds more than its share of them; nor while a request is with the
  // Handler (or held there).
  if (!may_read()) {
    read_paused_ = true;
    return;
  }
  static_assert(std::tuple_size_v<decltype(prefix_)> == wire::kLengthPrefixBytes);
  socket_.async_read(net::buffer(prefix_),
                     [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                       Lock lock(self->m_);
                       self->on_prefix(ec);
                     });
}

void Connection::on_prefix(const boost::system::error_code& ec) {
  if (stopped_) return;
  if (ec) {
    stop(wire::TlsSocket::peer_closed(ec) ? std::string("the client closed the connection")
                                          : "read failed: " + ec.message());
    return;
  }
  last_read_ = Clock::now();
  counters_.bytes_received += prefix_.size();
  const std::uint32_t length = wire::read_length_prefix(prefix_);
  if (auto s = wire::check_length(length, limits_.max_message_bytes); !s.ok()) {
    spdlog::warn("conn {}: bad length prefix: {}; closing", id_, s.error().message);
    stop("bad length prefix");
    return;
  }
  body_expected_ = length;
  body_received_ = 0;
  body_.clear();
  read_body();
}

void Connection::read_body() {
  // Grows as bytes arrive (a declared length alone reserves nothing).
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
    spdlog::warn("conn {}: truncated message: {} of {} bytes announced; closing", id_, body_received_,
                 body_expected_);
    stop(wire::TlsSocket::peer_closed(ec) ? std::string("truncated message") : "read failed: " + ec.message());
    return std::nullopt;
  }
  last_read_ = Clock::now();
  if (body_received_ < body_expected_) {
    read_body();
    return std::nullopt;
  }
  // The request goes to the Handler; reading waits until it is answered.
  std::string body = std::move(body_);
  body_ = std::string();  // a large request's buffer is not kept
  body_received_ = 0;
  at_handler_ = true;
  account();
  read_prefix();  // pauses: a request is with the Handler
  return body;
}

void Connection::hand_over(std::string body) {
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
  if (control_ == &io_) {
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
