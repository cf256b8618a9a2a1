#include "transport/ws_connection.h"

#include <google/protobuf/util/json_util.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cmath>

#include "gmr/wire/frames.h"
#include "gmr/wire/framing.h"
#include "prometheus/histogram.h"

namespace gmr::server {

namespace {
// How long a closing handshake may take before the socket is simply closed.
constexpr auto kCloseGrace = std::chrono::seconds(2);
// A read buffer grown past this by a large request is not kept.
constexpr std::size_t kKeptReadBuffer = 256 * 1024;

// The framed message's body (after its length prefix).
std::string_view body_of(std::string_view framed) { return framed.substr(wire::kLengthPrefixBytes); }

// A number as protobuf's JSON mapping writes it: the shortest text that
// reads back to the same value; NaN and the infinities as strings.
template <class T>
void append_number(std::string& out, T v) {
  if (std::isnan(v)) {
    out += "\"NaN\"";
  } else if (std::isinf(v)) {
    out += v > 0 ? "\"Infinity\"" : "\"-Infinity\"";
  } else {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    out.append(buf, r.ptr);
  }
}

void append_uint(std::string& out, std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

// "name": v, left out at its default (proto3 JSON leaves defaults out).
// 64-bit integers are strings in the mapping.
struct JsonObject {
  std::string& out;
  bool first = true;
  void key(const char* name) {
    out += first ? "\"" : ",\"";
    first = false;
    out += name;
    out += "\":";
  }
  void u32(const char* name, std::uint32_t v) {
    if (v == 0) return;
    key(name);
    append_uint(out, v);
  }
  void u64(const char* name, std::uint64_t v) {
    if (v == 0) return;
    key(name);
    out += '"';
    append_uint(out, v);
    out += '"';
  }
  void i64(const char* name, std::int64_t v) {
    if (v == 0) return;
    key(name);
    out += '"';
    if (v < 0) out += '-';
    append_uint(out, v < 0 ? 0 - static_cast<std::uint64_t>(v) : static_cast<std::uint64_t>(v));
    out += '"';
  }
  void f64(const char* name, double v) {
    if (v == 0.0 && !std::signbit(v)) return;
    key(name);
    append_number(out, v);
  }
  template <class Repeated>
  void array(const char* name, const Repeated& values) {
    if (values.empty()) return;
    key(name);
    out += '[';
    for (int i = 0; i < values.size(); ++i) {
      if (i != 0) out += ',';
      append_number(out, values.Get(i));
    }
    out += ']';
  }
};
}  // namespace

std::string frame_to_json(const pb::ServerMessage& m) {
  const pb::Frame& f = m.frame();
  std::string out;
  out.reserve(64 + 24 * static_cast<std::size_t>(f.positions_size() + f.positions_f64_size() + f.orientations_size() +
                                                 f.orientations_f64_size() + f.local_rotations_size() +
                                                 f.local_rotations_f64_size() + f.local_translations_size() +
                                                 f.local_translations_f64_size()));
  out += '{';
  JsonObject top{out};
  top.u64("requestId", m.request_id());
  top.key("frame");
  out += '{';
  JsonObject o{out};
  o.u32("viewId", f.view_id());
  o.u32("subscriptionId", f.subscription_id());
  o.u64("streamId", f.stream_id());
  o.u32("skeletonVersion", f.skeleton_version());
  o.u64("frameIndex", f.frame_index());
  o.f64("motionTime", f.motion_time());
  o.u64("sequence", f.sequence());
  o.i64("serverSendTimeNs", f.server_send_time_ns());
  o.i64("serverWriteTimeNs", f.server_write_time_ns());
  o.array("positions", f.positions());
  o.array("orientations", f.orientations());
  o.array("positionsF64", f.positions_f64());
  o.array("orientationsF64", f.orientations_f64());
  o.array("localRotations", f.local_rotations());
  o.array("localTranslations", f.local_translations());
  o.array("localRotationsF64", f.local_rotations_f64());
  o.array("localTranslationsF64", f.local_translations_f64());
  out += "}}";
  return out;
}

WsConnection::WsConnection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
                           BufferBudget* budget)
    : ws_(std::move(socket)),
      id_(id),
      limits_(limits),
      budget_(budget),
      frames_(limits.frames_per_key, limits.max_frame_bytes),
      watchdog_(io) {
  boost::system::error_code ec;
  const auto ep = beast::get_lowest_layer(ws_).socket().remote_endpoint(ec);
  peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
}

WsConnection::~WsConnection() {
  if (budget_ != nullptr) budget_->release(accounted_);
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
  timeouts.handshake_timeout = limits_.handshake_timeout.count() > 0
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
  spdlog::info("conn {}: WebSocket ({}) from {}", id_, protocol, peer_);
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

void WsConnection::account() {
  if (budget_ != nullptr) budget_->settle(accounted_, queued_bytes() + in_.size());
}

void WsConnection::hold_reading(bool hold) {
  reads_held_ = hold;
  if (!hold && read_paused_ && may_read()) {
    read_paused_ = false;
    read();
  }
}

bool WsConnection::may_read() const {
  return !reads_held_ && reply_bytes_ + in_flight_bytes_ <= limits_.max_reply_queue_bytes &&
         (budget_ == nullptr || budget_->allows_reading(accounted_));
}

void WsConnection::read() {
  if (stopped_ || reading_) return;
  if (!may_read()) {  // back-pressure, as over TCP
    read_paused_ = true;
    return;
  }
  reading_ = true;
  ws_.async_read(in_, [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
    self->on_read(ec, n);
  });
}

void WsConnection::on_read(const boost::system::error_code& ec, std::size_t bytes) {
  reading_ = false;
  if (stopped_) return;
  if (ec) {
    if (ec == websocket::error::message_too_big) {
      spdlog::warn("conn {}: a WebSocket message longer than {} bytes; closing", id_, limits_.max_message_bytes);
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
  std::string body = beast::buffers_to_string(in_.data());
  in_.consume(in_.size());
  if (in_.capacity() > kKeptReadBuffer) in_ = beast::flat_buffer();
  if (ws_.got_text()) {
    // protobuf's JSON mapping of a ClientMessage: parsed here, so the
    // handler sees the same bytes a TCP client would send.
    pb::ClientMessage m;
    google::protobuf::util::JsonParseOptions options;
    options.ignore_unknown_fields = false;
    if (auto status = google::protobuf::util::JsonStringToMessage(body, &m, options); !status.ok()) {
      send(wire::frame_message(error_message(0, pb::ERROR_CODE_BAD_REQUEST,
                                             "cannot parse the text message as the JSON of a "
                                             "gmr.stream.v1.ClientMessage: " +
                                                 std::string(status.message())))
               .value());
      read();
      return;
    }
    body = m.SerializeAsString();
  }
  handler_->on_message(body);
  account();
  read();
}

void WsConnection::send(std::string framed) {
  if (stopped_) return;
  reply_bytes_ += framed.size();
  replies_.push_back(std::move(framed));
  counters_.max_queued_bytes = std::max(counters_.max_queued_bytes, queued_bytes());
  account();
  flush();
}

bool WsConnection::push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body,
                              Clock::duration max_age) {
  if (closing()) return true;
  const Clock::time_point now = Clock::now();
  const Clock::time_point stale_at = max_age > Clock::duration::zero() ? now + max_age : Clock::time_point::max();
  const bool kept_all = frames_.push(key, PendingFrame{std::move(head), std::move(body), stale_at, now},
                                     writing_ || !open_, budget_ != nullptr && budget_->over(), counters_);
  counters_.max_queued_bytes = std::max(counters_.max_queued_bytes, queued_bytes());
  account();
  flush();
  return kept_all;
}


bool WsConnection::congested(std::uint32_t key) const {
  if (!writing_ || stopped_) return false;
  if (budget_ != nullptr && budget_->over()) return true;
  return frames_.waiting(key) && Clock::now() - write_started_ > limits_.congested_after;
}

void WsConnection::discard_frames(std::uint32_t key) {
  frames_.discard(key);
  account();
}

void WsConnection::send_frames_now(std::uint32_t key) {
  const std::int64_t now = now_ns();
  for (auto& f : frames_.take(key)) {
    std::string framed = std::move(f.head);
    wire::set_write_stamp(framed, now);
    framed += *f.body;
    reply_bytes_ += framed.size();
    replies_.push_back(std::move(framed));
    ++counters_.frames_sent;
  }
  account();
}

std::uint64_t WsConnection::end_frames(std::uint32_t key) {
  const std::uint64_t stale = frames_.stale_dropped(key);
  send_frames_now(key);
  discard_frames(key);
  return stale;
}

void WsConnection::close_after_reply() {
  close_after_flush_ = true;
  frames_.clear();
  account();
}

void WsConnection::finish() {
  close_after_reply();
  flush();
}

ConnectionCounters WsConnection::counters() const {
  ConnectionCounters c = counters_;
  c.queued_bytes = queued_bytes();
  return c;
}

std::string WsConnection::to_client(std::string_view framed) const {
  const std::string_view body = body_of(framed);
  if (format_ == Format::kBinary) return std::string(body);
  pb::ServerMessage m;
  std::string json;
  if (!m.ParseFromArray(body.data(), static_cast<int>(body.size()))) {
    spdlog::error("conn {}: cannot parse a {}-byte message to write it as JSON", id_, body.size());
    return {};
  }
  if (m.has_frame()) return frame_to_json(m);  // the message sent most, converted fast
  if (!google::protobuf::util::MessageToJsonString(m, &json, google::protobuf::util::JsonPrintOptions()).ok()) {
    spdlog::error("conn {}: cannot write a {}-byte message as JSON", id_, body.size());
    return {};
  }
  return json;
}

void WsConnection::flush() {
  if (writing_ || stopped_ || !open_) return;
  if (!replies_.empty()) {
    std::string message = to_client(replies_.front());
    reply_bytes_ -= replies_.front().size();
    replies_.pop_front();
    write(std::move(message), false);
    return;
  }
  // One frame per message, the subscriptions taking turns.
  if (auto f = frames_.pop_next(next_key_, Clock::now(), counters_)) {
    std::string framed = std::move(f->head);
    wire::set_write_stamp(framed, now_ns());
    framed += *f->body;
    ++counters_.frames_sent;
    frame_in_flight_pushed_ = f->pushed_at;
    write(to_client(framed), true);
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
  write_started_ = Clock::now();
  account();
  ws_.text(format_ == Format::kJson);
  ws_.async_write(net::buffer(out_), [self = shared_from_this(), frame](const boost::system::error_code& ec,
                                                                         std::size_t n) {
    self->writing_ = false;
    self->in_flight_bytes_ = 0;
    if (self->out_.capacity() > kKeptReadBuffer) std::string().swap(self->out_);
    self->account();
    if (ec) {
      if (!self->stopped_) self->stop("write failed: " + ec.message());
      self->close_socket();
      return;
    }
    self->counters_.bytes_sent += n;
    self->last_write_ = Clock::now();
    if (frame) {
      self->last_frames_written_ = self->last_write_;
      if (self->frame_wait_ != nullptr) {
        self->frame_wait_->Observe(
            std::chrono::duration<double>(self->last_write_ - self->frame_in_flight_pushed_).count());
      }
    }
    if (self->stopped_) {
      self->close_socket();
      return;
    }
    if (self->read_paused_ && self->may_read()) {
      self->read_paused_ = false;
      self->read();
    }
    self->flush();
  });
}

void WsConnection::stop(const std::string& reason) {
  if (stopped_) return;
  stopped_ = true;
  spdlog::info("conn {}: closed: {} (frames sent {}, dropped {})", id_, reason, counters_.frames_sent,
               counters_.frames_dropped);
  if (handler_) handler_->on_stop();
  frames_.clear();
  replies_.clear();
  reply_bytes_ = 0;
  account();
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
  watchdog_.expires_after(watchdog_period(limits_, established_));
  watchdog_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    if (ec || self->stopped_) return;
    const auto now = Clock::now();
    if (self->reads_held_) self->last_read_ = now;  // waiting for the server (an edit): not idle
    const LinkTimes times{self->established_, self->writing_,       self->started_,
                          self->last_read_,   self->write_started_, self->last_frames_written_};
    if (std::string why = watchdog_verdict(times, self->limits_, now, self->id_); !why.empty()) {
      self->stop(why);
      return;
    }
    if (self->read_paused_ && self->may_read()) {
      self->read_paused_ = false;
      self->read();
    }
    if (self->open_ && !self->writing_ && now - self->last_write_ > self->limits_.heartbeat_interval) {
      self->send(heartbeat_message());
      self->last_write_ = now;
    }
    self->arm_watchdog();
  });
}

}  // namespace gmr::server
