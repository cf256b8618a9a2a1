#include "connection.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>

#include "gmr/wire/framing.h"

namespace gmr::server {

Connection::Connection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits)
    : socket_(std::move(socket)), id_(id), limits_(limits), watchdog_(io) {
  boost::system::error_code ec;
  auto ep = socket_.remote_endpoint(ec);
  peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
}

void Connection::start(std::shared_ptr<Handler> handler, std::function<void(std::uint64_t)> on_closed) {
  handler_ = std::move(handler);
  on_closed_ = std::move(on_closed);
  boost::system::error_code ec;
  socket_.set_option(tcp::no_delay(true), ec);
  if (limits_.socket_send_buffer > 0) {
    socket_.set_option(net::socket_base::send_buffer_size(limits_.socket_send_buffer), ec);
  }
  last_read_ = last_write_ = Clock::now();
  spdlog::info("conn {}: connected from {}", id_, peer_);
  read_prefix();
  arm_watchdog();
}

void Connection::stop(const std::string& reason) {
  if (stopped_) return;
  stopped_ = true;
  spdlog::info("conn {}: closed: {} (frames sent {}, dropped {})", id_, reason, counters_.frames_sent,
               counters_.frames_dropped);
  if (handler_) handler_->on_stop();
  frames_.clear();
  replies_.clear();
  reply_bytes_ = 0;
  boost::system::error_code ec;
  socket_.shutdown(tcp::socket::shutdown_both, ec);
  socket_.close(ec);
  watchdog_.cancel();
  if (on_closed_) on_closed_(id_);
}

void Connection::finish() {
  close_after_reply();
  flush();
}

void Connection::close_after_reply() {
  close_after_flush_ = true;
  frames_.clear();
}

void Connection::send(std::string framed) {
  if (stopped_) return;
  reply_bytes_ += framed.size();
  replies_.push_back(std::make_shared<const std::string>(std::move(framed)));
  note_queue();
  flush();
}

bool Connection::push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body) {
  if (closing()) return true;
  bool kept_all = true;
  auto& queue = frames_[key];
  if (queue.size() >= std::max<std::size_t>(1, limits_.frames_per_key)) {
    queue.pop_front();
    ++counters_.frames_dropped;
    kept_all = false;
  }
  queue.push_back(PendingFrame{std::move(head), std::move(body)});
  note_queue();
  flush();
  return kept_all;
}

void Connection::discard_frames(std::uint32_t key) { frames_.erase(key); }

void Connection::send_frames_now(std::uint32_t key) {
  auto it = frames_.find(key);
  if (it == frames_.end()) return;
  for (const auto& frame : it->second) {
    auto bytes = std::make_shared<const std::string>(frame.head + *frame.body);
    reply_bytes_ += bytes->size();
    replies_.push_back(std::move(bytes));
    ++counters_.frames_sent;
  }
  frames_.erase(it);
}

std::uint64_t Connection::queued_bytes() const {
  std::uint64_t n = reply_bytes_ + in_flight_bytes_;
  for (const auto& [key, queue] : frames_) {
    for (const auto& f : queue) n += f.head.size() + f.body->size();
  }
  return n;
}

void Connection::note_queue() { counters_.max_queued_bytes = std::max(counters_.max_queued_bytes, queued_bytes()); }

ConnectionCounters Connection::counters() const {
  ConnectionCounters c = counters_;
  c.queued_bytes = queued_bytes();
  return c;
}

void Connection::flush() {
  if (writing_ || stopped_) return;
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
  std::size_t frames = 0;
  for (const auto& [key, queue] : frames_) frames += queue.size();
  hold_heads_.reserve(frames);
  for (auto& [key, queue] : frames_) {
    for (auto& f : queue) {
      hold_heads_.push_back(std::move(f.head));
      in_flight_bytes_ += hold_heads_.back().size() + f.body->size();
      hold_.push_back(std::move(f.body));
      ++counters_.frames_sent;
    }
  }
  // Buffers point into hold_heads_ (reserved, so stable) and the held bodies.
  std::size_t head_index = 0;
  for (std::size_t i = buffers.size(); i < hold_.size(); ++i, ++head_index) {
    buffers.push_back(net::buffer(hold_heads_[head_index]));
    buffers.push_back(net::buffer(*hold_[i]));
  }
  frames_.clear();
  writing_ = true;
  write_started_ = Clock::now();
  net::async_write(socket_, buffers, [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
    self->writing_ = false;
    self->hold_.clear();
    self->hold_heads_.clear();
    self->in_flight_bytes_ = 0;
    if (ec) {
      if (ec != net::error::operation_aborted) self->stop("write failed: " + ec.message());
      return;
    }
    self->last_write_ = Clock::now();
    if (self->read_paused_ && self->reply_bytes_ <= self->limits_.max_reply_queue_bytes) {
      self->read_paused_ = false;
      self->read_prefix();
    }
    self->flush();
  });
}

void Connection::arm_watchdog() {
  using std::chrono::milliseconds;
  const auto& l = limits_;
  const auto period = std::max(milliseconds(10), std::min({l.heartbeat_interval, l.idle_timeout, l.write_timeout}) / 4);
  watchdog_.expires_after(period);
  watchdog_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    if (ec || self->stopped_) return;
    const auto now = Clock::now();
    const auto& lim = self->limits_;
    if (now - self->last_read_ > lim.idle_timeout) {
      spdlog::warn("conn {}: idle for more than {} ms", self->id_, lim.idle_timeout.count());
      self->stop("idle timeout");
      return;
    }
    if (self->writing_ && now - self->write_started_ > lim.write_timeout) {
      spdlog::warn("conn {}: a write made no progress for {} ms: the client is not reading", self->id_,
                   lim.write_timeout.count());
      self->stop("write timeout");
      return;
    }
    if (!self->writing_ && now - self->last_write_ > lim.heartbeat_interval) {
      pb::ServerMessage hb;
      hb.mutable_heartbeat()->set_client_time_ns(0);
      self->send(wire::frame_message(hb).value());
      self->last_write_ = now;
    }
    self->arm_watchdog();
  });
}

void Connection::read_prefix() {
  if (stopped_) return;
  // Back-pressure: a client that sends requests faster than it reads the
  // replies is not read until they drain; its replies never pile up beyond the cap.
  if (reply_bytes_ > limits_.max_reply_queue_bytes) {
    read_paused_ = true;
    return;
  }
  static_assert(std::tuple_size_v<decltype(prefix_)> == wire::kLengthPrefixBytes);
  net::async_read(socket_, net::buffer(prefix_), [self = shared_from_this()](const boost::system::error_code& ec,
                                                                             std::size_t) { self->on_prefix(ec); });
}

void Connection::on_prefix(const boost::system::error_code& ec) {
  if (stopped_) return;
  if (ec) {
    stop(ec == net::error::eof ? std::string("the client closed the connection") : "read failed: " + ec.message());
    return;
  }
  last_read_ = Clock::now();
  const std::uint32_t length = wire::read_length_prefix(prefix_);
  if (auto s = wire::check_length(length, limits_.max_message_bytes); !s.ok()) {
    spdlog::warn("conn {}: bad length prefix: {}; closing", id_, s.error().message);
    stop("bad length prefix");
    return;
  }
  body_.resize(length);
  net::async_read(socket_, net::buffer(body_), [self = shared_from_this()](const boost::system::error_code& e,
                                                                           std::size_t got) { self->on_body(e, got); });
}

void Connection::on_body(const boost::system::error_code& ec, std::size_t got) {
  if (stopped_) return;
  if (ec) {
    spdlog::warn("conn {}: truncated message: {} of {} bytes announced; closing", id_, got, body_.size());
    stop(ec == net::error::eof ? std::string("truncated message") : "read failed: " + ec.message());
    return;
  }
  last_read_ = Clock::now();
  handler_->on_message(body_);
  read_prefix();
}

}  // namespace gmr::server
