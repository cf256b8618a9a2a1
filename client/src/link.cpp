#include "client_impl.h"

#include <array>
#include <cstring>

namespace gmr::client {

bool Client::Impl::send(std::string framed) {
  const std::size_t n = framed.size();
  const std::size_t before = write_queue_bytes.fetch_add(n);
  if (before > 0 && before + n > options.max_write_queue_bytes) {
    write_queue_bytes -= n;
    return false;
  }
  net::post(strand, [self = shared_from_this(), framed = std::move(framed)]() mutable {
    if (!self->open) {
      self->write_queue_bytes -= framed.size();
      return;
    }
    self->write_queue.push_back(std::move(framed));
    self->write_next();
  });
  return true;
}

void Client::Impl::write_next() {
  if (writing || write_queue.empty()) return;
  writing = true;
  socket.async_write(net::buffer(write_queue.front()),
                     [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                       self->writing = false;
                       if (!self->write_queue.empty()) {
                         self->write_queue_bytes -= self->write_queue.front().size();
                         self->write_queue.pop_front();
                       }
                       if (ec) return self->fail("write failed: " + ec.message());
                       self->write_next();
                     });
}

namespace {
// Bytes of room a read gets at least; a message longer than what is held
// makes room for itself (within max_message_bytes). Once a long message is
// through, a buffer past kKeptReadBuffer is given back.
constexpr std::size_t kReadChunk = 4096;
constexpr std::size_t kKeptReadBuffer = 64 * 1024;
}  // namespace

void Client::Impl::read_more() {
  if (in_.size() - in_end_ < kReadChunk) in_.resize(in_end_ + kReadChunk);
  socket.async_read_some(net::buffer(in_.data() + in_end_, in_.size() - in_end_),
                         [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
                           if (ec) {
                             return self->fail(asio::TlsSocket::peer_closed(ec)
                                                   ? std::string("the server closed the connection")
                                                   : "read failed: " + ec.message());
                           }
                           self->in_end_ += n;
                           if (self->take_messages()) self->read_more();
                         });
}

bool Client::Impl::take_messages() {
  std::size_t at = 0;
  std::uint32_t next = 0;  // the length of the message at `at`, once its prefix is in
  bool whole = false;
  for (;;) {
    if (in_end_ - at < wire::kLengthPrefixBytes) break;
    std::array<std::uint8_t, wire::kLengthPrefixBytes> prefix{};
    std::memcpy(prefix.data(), in_.data() + at, prefix.size());
    next = wire::read_length_prefix(prefix);
    if (auto s = wire::check_length(next, options.max_message_bytes); !s.ok()) {
      fail("bad length prefix from the server: " + s.error().message);
      return false;
    }
    whole = in_end_ - at - wire::kLengthPrefixBytes >= next;
    if (!whole) break;
    const std::string_view message(in_.data() + at + wire::kLengthPrefixBytes, next);
    at += wire::kLengthPrefixBytes + next;
    if (!take_message(message, false)) {
      fail("the server sent a message that does not parse");
      return false;
    }
    if (!open) return false;
  }
  // What is left (part of a message) moves to the front.
  std::memmove(in_.data(), in_.data() + at, in_end_ - at);
  in_end_ -= at;
  if (in_end_ >= wire::kLengthPrefixBytes && !whole) {
    // A message longer than the buffer: room for all of it.
    const std::size_t need = wire::kLengthPrefixBytes + next;
    if (in_.size() < need) in_.resize(need);
  } else if (in_end_ == 0 && in_.size() > kKeptReadBuffer) {
    std::string().swap(in_);
  }
  return true;
}

void Client::Impl::arm_heartbeat() {
  // As often as the server's idle rule needs: a third of its idle timeout
  // (without one, its heartbeat interval), 10 ms at the least. Before, it was
  // the server's heartbeat interval when shorter (then 5 s against 10 s by
  // default): twice the heartbeats the rule needs, each a wake-up and a read
  // for the server (docs/performance.md, "Multicast's keep-alive").
  const std::uint32_t idle_third = hello.idle_timeout_ms / 3;
  const auto interval = std::chrono::milliseconds(
      std::max<std::uint32_t>(10, idle_third != 0 ? idle_third : hello.heartbeat_interval_ms));
  heartbeat.expires_after(interval);
  heartbeat.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    if (ec || !self->open) return;
    pb::ClientMessage m;
    m.mutable_heartbeat()->set_client_time_ns(static_cast<std::uint64_t>(now_ns()));
    self->send(wire::frame_message(m).value());  // a full queue already keeps the link busy
    self->arm_heartbeat();
  });
}

void Client::Impl::on_answer(const pb::ServerMessage& m) {
  Pending p;
  {
    std::lock_guard lock(mutex);
    auto it = pending.find(m.request_id());
    if (it == pending.end()) {
      if (m.has_error()) {
        if (async_errors.size() == kMaxAsyncErrors) async_errors.pop_front();
        async_errors.push_back(std::string(wire::error_code_name(m.error().code())) + ": " + m.error().message());
      }
      return;
    }
    p = std::move(it->second);
    pending.erase(it);
  }
  if (p.on_reply) p.on_reply(m);
  p.promise.set_value(m);
}

void Client::Impl::shut() {
  boost::system::error_code ec;
  socket.tcp().close(ec);
  udp_socket.close(ec);
  if (multicast_socket) multicast_socket->close(ec);
  heartbeat.cancel();
  std::vector<std::shared_ptr<net::steady_timer>> timers;
  {
    std::lock_guard lock(mutex);
    for (const auto& [id, sub] : subs) {
      if (sub->ending_timer) timers.push_back(sub->ending_timer);
    }
  }
  for (const auto& t : timers) t->cancel();
}

void Client::Impl::fail(const std::string& reason) {
  if (!open.exchange(false)) return;
  shut();
  std::map<std::uint64_t, Pending> orphans;
  {
    std::lock_guard lock(mutex);
    if (close_reason.empty()) close_reason = reason;
    orphans.swap(pending);
    udp_cv.notify_all();
  }
  for (auto& [id, p] : orphans) p.promise.set_value(std::nullopt);
}

Result<pb::ServerMessage> Client::Impl::call(pb::ClientMessage m,
                                             std::function<void(const pb::ServerMessage&)> on_reply) {
  const std::uint64_t id = next_request++;
  m.set_request_id(id);
  auto framed = wire::frame_message(m, 1u << 30);
  if (!framed.ok()) return framed.error();
  std::future<std::optional<pb::ServerMessage>> future;
  {
    std::lock_guard lock(mutex);
    if (!open) return make_error("not connected: " + close_reason);
    Pending p;
    p.on_reply = std::move(on_reply);
    future = p.promise.get_future();
    pending.emplace(id, std::move(p));
  }
  if (!send(std::move(framed).value())) {
    std::lock_guard lock(mutex);
    pending.erase(id);
    return make_error(ErrorKind::kResourceExhausted,
                      "write queue full: " + std::to_string(write_queue_bytes.load()) +
                          " bytes of requests wait for the server to read them (max_write_queue_bytes " +
                          std::to_string(options.max_write_queue_bytes) + ")");
  }
  if (future.wait_for(options.timeout) != std::future_status::ready) {
    std::lock_guard lock(mutex);
    pending.erase(id);
    return make_error("no reply from the server within " + std::to_string(options.timeout.count()) + " ms");
  }
  std::optional<pb::ServerMessage> reply = future.get();
  if (reply) return std::move(*reply);
  std::lock_guard lock(mutex);
  return make_error("connection lost: " + close_reason);
}

Result<pb::ServerMessage> Client::Impl::expect(pb::ClientMessage m, pb::ServerMessage::BodyCase expected,
                                               std::function<void(const pb::ServerMessage&)> on_reply) {
  auto r = call(std::move(m), std::move(on_reply));
  if (!r.ok()) return r;
  if (r->has_error()) {
    return make_error(std::string(wire::error_code_name(r->error().code())) + ": " + r->error().message());
  }
  if (r->body_case() != expected) return make_error("unexpected reply from the server");
  return r;
}

Status Client::Impl::start_tls(const std::string& where) {
  const auto& t = options.tls;
  const std::string name = t.server_name.empty() ? options.host : t.server_name;
  boost::system::error_code ec;
  tls_context.emplace(net::ssl::context::tls_client);
  auto& ctx = *tls_context;
  ctx.set_options(net::ssl::context::default_workarounds | net::ssl::context::no_sslv2 | net::ssl::context::no_sslv3 |
                  net::ssl::context::no_tlsv1 | net::ssl::context::no_tlsv1_1);
  if (t.ca_file.empty()) {
    ctx.set_default_verify_paths(ec);
  } else {
    ctx.load_verify_file(t.ca_file, ec);
  }
  if (ec) {
    return make_error(ErrorKind::kIo, "cannot load the TLS trust " +
                                          (t.ca_file.empty() ? std::string("store") : "file " + t.ca_file) + ": " +
                                          ec.message());
  }
  ctx.set_verify_mode(net::ssl::verify_peer);
  auto name_matched = std::make_shared<bool>(true);
  ctx.set_verify_callback(
      [check = net::ssl::host_name_verification(name), name_matched](bool preverified, net::ssl::verify_context& v) {
        const bool ok = check(preverified, v);
        if (preverified && !ok) *name_matched = false;
        return ok;
      });
  socket.use_tls(ctx);
  // Server Name Indication for a name (never for an address).
  net::ip::make_address(name, ec);
  if (ec) SSL_set_tlsext_host_name(socket.tls_stream().native_handle(), name.c_str());
  auto done = std::make_shared<std::promise<boost::system::error_code>>();
  auto result = done->get_future();
  net::post(strand, [self = shared_from_this(), done] {
    self->socket.tls_stream().async_handshake(net::ssl::stream_base::client,
                                              [done](const boost::system::error_code& e) { done->set_value(e); });
  });
  if (result.wait_for(options.timeout) != std::future_status::ready) {
    net::post(strand, [self = shared_from_this()] {
      boost::system::error_code e;
      self->socket.tcp().close(e);
    });
    result.wait();
    return make_error("TLS handshake with " + where + ": timed out");
  }
  if (auto e = result.get()) {
    std::string why = e.message();
    if (!*name_matched) {
      why += " (the certificate does not name '" + name + "')";
    } else if (const long v = SSL_get_verify_result(socket.tls_stream().native_handle()); v != X509_V_OK) {
      why += std::string(" (") + X509_verify_cert_error_string(v) + ")";
    }
    return make_error("TLS handshake with " + where + " failed: " + why);
  }
  return Ok{};
}

}  // namespace gmr::client
