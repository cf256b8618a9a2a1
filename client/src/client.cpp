#include "gmr/client/client.h"

#include <algorithm>
#include <charconv>
#include <atomic>
#include <boost/asio.hpp>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <future>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "gmr/stream/v1/stream.pb.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/frames.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/tls_socket.h"
#include "gmr/wire/udp.h"

namespace gmr::client {

namespace pb = ::gmr::stream::v1;

namespace net = boost::asio;
using tcp = net::ip::tcp;
using udp = net::ip::udp;

namespace {

// A native convention is sent as nothing at all (what an old client sends).
void to_proto(const Conventions& c, pb::Conventions& out) {
  if (c.preset == ConventionPreset::kNative) return;
  out.set_preset(static_cast<pb::ConventionPreset>(c.preset));
  if (c.preset == ConventionPreset::kCustom) {
    out.set_up(c.up);
    out.set_forward(c.forward);
    out.set_left_handed(c.left_handed);
    out.set_target_metres_per_unit(c.target_metres_per_unit);
  }
  out.set_source_metres_per_unit(c.source_metres_per_unit);
}


std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

ServerHello hello_of(const pb::HelloReply& h) {
  ServerHello s;
  s.protocol_version = h.protocol_version();
  s.server_name = h.server_name();
  if (h.udp_token().size() == s.udp_token.size()) std::memcpy(s.udp_token.data(), h.udp_token().data(), s.udp_token.size());
  s.udp_port = static_cast<std::uint16_t>(h.udp_port());
  s.max_message_bytes = h.max_message_bytes();
  s.heartbeat_interval_ms = h.heartbeat_interval_ms();
  s.idle_timeout_ms = h.idle_timeout_ms();
  s.role = h.role() == pb::ROLE_PUBLISH   ? Role::kPublish
           : h.role() == pb::ROLE_CONTROL ? Role::kControl
           : h.role() == pb::ROLE_READ    ? Role::kRead
                                          : Role::kUnknown;
  return s;
}

// How many frames an ended subscription's client gets: those the server
// counted against it, less those it dropped (slow client, staleness) or
// skipped (late server).
std::uint64_t frames_to_come(const SubscriptionEnd& e) {
  const std::uint64_t gone = e.frames_dropped + e.frames_skipped;
  return e.frames_sent > gone ? e.frames_sent - gone : 0;
}

SubscriptionEnd end_of(const pb::SubscriptionEnded& e) {
  return SubscriptionEnd{e.subscription_id(), e.frames_sent(), e.frames_dropped(), e.reason(), e.frames_skipped(),
                         e.frames_stale()};
}

}  // namespace

// The io_context a client's handlers run on: its own (one thread, started
// by connect()) or an EventLoop's, shared with other clients.
struct Loop {
  Loop() : owned(std::make_unique<net::io_context>()), io(*owned) {}
  explicit Loop(net::io_context& caller) : io(caller) {}
  std::unique_ptr<net::io_context> owned;  // null: the caller's
  net::io_context& io;
  // True on a thread inside io.run() (a callback): close() must not wait there.
  bool runs_here() const { return io.get_executor().running_in_this_thread(); }
};

struct EventLoop::Impl {
  explicit Impl(std::shared_ptr<Loop> l) : loop(std::move(l)) {}
  std::shared_ptr<Loop> loop;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> guard;
  std::vector<std::thread> threads;
};

EventLoop::EventLoop(unsigned threads) : impl_(std::make_unique<Impl>(std::make_shared<Loop>())) {
  impl_->guard.emplace(impl_->loop->io.get_executor());
  const unsigned n = std::max(1u, threads);
  for (unsigned i = 0; i < n; ++i) impl_->threads.emplace_back([loop = impl_->loop] { loop->io.run(); });
}

EventLoop::EventLoop(net::io_context& io) : impl_(std::make_unique<Impl>(std::make_shared<Loop>(io))) {}

EventLoop::~EventLoop() {
  if (impl_->threads.empty()) return;  // the caller's io_context: the caller runs and stops it
  impl_->guard.reset();
  impl_->loop->io.stop();
  for (auto& t : impl_->threads) {
    if (t.get_id() == std::this_thread::get_id()) {
      t.detach();
    } else {
      t.join();
    }
  }
}

unsigned EventLoop::threads() const { return static_cast<unsigned>(impl_->threads.size()); }  // 0: the caller's

struct Client::Impl : std::enable_shared_from_this<Impl> {
  explicit Impl(std::shared_ptr<Loop> l) : loop(std::move(l)), io(loop->io), strand(net::make_strand(io)) {}

  ClientOptions options;
  std::shared_ptr<Loop> loop;
  net::io_context& io;
  // Every handler of this client runs on its strand, so a loop with several
  // threads never runs two of them at once.
  net::strand<net::io_context::executor_type> strand;
  bool own_loop = true;
  std::atomic<bool> closed{false};
  std::optional<net::ssl::context> tls_context;  // options.tls.enabled; outlives the socket
  wire::TlsSocket socket{net::any_io_executor(strand)};
  udp::socket udp_socket{strand};
  udp::endpoint server_udp;
  net::steady_timer heartbeat{strand};
  std::thread thread;  // own loop only
  // Own loop: keeps run() going until close(); then the loop ends once every
  // handler has completed (never io.stop(): a handler left queued would keep
  // Impl alive).
  std::optional<net::executor_work_guard<net::io_context::executor_type>> guard;
  ServerHello hello;

  std::atomic<bool> open{false};
  std::atomic<std::uint64_t> next_request{1};
  // A reply, or nullopt when the connection failed first (close_reason says
  // why). Not an exception: an exception object shared by two threads is
  // freed by whichever releases it last, which ThreadSanitizer cannot see
  // through the uninstrumented libstdc++ and reports as a race.
  struct Pending {
    std::promise<std::optional<pb::ServerMessage>> promise;
    std::function<void(const pb::ServerMessage&)> on_reply;  // runs on the I/O thread before the promise is set
  };
  mutable std::mutex mutex;
  std::map<std::uint64_t, Pending> pending;
  struct Sub {
    FrameCallback on_frame;
    EndCallback on_end;
    SkeletonCallback on_skeleton;
    std::int64_t max_age_ns = 0;  // 0: no staleness bound
    std::uint64_t stream_id = 0;  // multicast: frames carry the stream's id, not the subscription's
    bool multicast = false;
    // The skeleton version the callbacks were last told of (the Subscribed
    // reply, then each SkeletonChanged). A frame of another version is not
    // that skeleton's (a UDP frame of the new version can overtake its
    // SkeletonChanged, a queued TCP frame of the old one can follow it): it
    // is dropped and counted, so on_frame only sees frames of the skeleton
    // it knows. Under mutex.
    std::uint32_t skeleton_version = 0;
    // Frames that came for it, whatever became of them (under mutex), and
    // its end notice when that came before frames it counts (a UDP frame
    // can be overtaken by the TCP notice): held until they are all here or
    // kEndGrace passed, so on_end is the last callback and the last frames
    // are not lost.
    std::uint64_t arrived = 0;
    std::optional<SubscriptionEnd> ending{};
    std::shared_ptr<net::steady_timer> ending_timer{};
  };
  static constexpr auto kEndGrace = std::chrono::milliseconds(100);
  // The multicast group's socket (the first multicast subscription opens it).
  std::optional<udp::socket> multicast_socket;
  udp::endpoint multicast_sender;
  std::array<char, 2048> multicast_buffer{};
  wire::Reassembler multicast_reassembler;
  std::map<std::uint32_t, std::shared_ptr<Sub>> subs;
  // A UDP frame can overtake the TCP reply to its Subscribe: frames for an
  // unknown subscription wait here (bounded) while a Subscribe is in flight.
  int subscribes_in_flight = 0;
  std::deque<std::pair<pb::ServerMessage, bool>> early_frames;
  static constexpr std::size_t kMaxEarlyFrames = 256;
  std::string close_reason;
  bool udp_registered = false;
  std::condition_variable udp_cv;
  ClientCounters counters;
  std::deque<std::string> async_errors;  // for requests that get no reply
  static constexpr std::size_t kMaxAsyncErrors = 64;

  // I/O-thread state
  std::deque<std::string> write_queue;
  std::atomic<std::size_t> write_queue_bytes{0};  // also read by callers of send()
  bool writing = false;
  std::array<std::uint8_t, wire::kLengthPrefixBytes> prefix{};
  std::string body;
  std::array<char, 2048> udp_buffer{};
  udp::endpoint udp_sender;
  wire::Reassembler reassembler;

  // Queues `framed` for the socket; false (nothing queued) when it would take
  // a non-empty queue past options.max_write_queue_bytes.
  bool send(std::string framed) {
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
  void write_next() {
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
  void read_prefix() {
    socket.async_read(net::buffer(prefix), [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
      if (ec) {
        return self->fail(wire::TlsSocket::peer_closed(ec) ? std::string("the server closed the connection")
                                                           : "read failed: " + ec.message());
      }
      const std::uint32_t n = wire::read_length_prefix(self->prefix);
      if (auto s = wire::check_length(n, self->options.max_message_bytes); !s.ok()) {
        return self->fail("bad length prefix from the server: " + s.error().message);
      }
      self->body.resize(n);
      self->socket.async_read(net::buffer(self->body), [self](const boost::system::error_code& ec2, std::size_t) {
        if (ec2) return self->fail("read failed: " + ec2.message());
        pb::ServerMessage m;
        if (!m.ParseFromString(self->body)) return self->fail("the server sent a message that does not parse");
        self->on_message(m, false);
        self->read_prefix();
      });
    });
  }
  void read_udp() {
    udp_socket.async_receive_from(net::buffer(udp_buffer), udp_sender,
                                  [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
                                    if (ec == net::error::operation_aborted || !self->open) return;
                                    // Only datagrams from the server's address count.
                                    if (!ec && self->udp_sender == self->server_udp) {
                                      const std::string_view d(self->udp_buffer.data(), n);
                                      if (auto cookie = wire::parse_challenge_datagram(d)) {
                                        // The server asks this address to prove it registered: echo.
                                        wire::UdpToken token;
                                        std::memcpy(token.data(), self->hello.udp_token.data(), token.size());
                                        const std::string confirm = wire::make_confirm_datagram(token, *cookie);
                                        boost::system::error_code send_ec;
                                        self->udp_socket.send_to(net::buffer(confirm), self->server_udp, 0, send_ec);
                                      } else if (auto msg = self->reassembler.add(d)) {
                                        pb::ServerMessage m;
                                        if (m.ParseFromString(*msg) && m.has_frame()) self->on_message(m, true);
                                      }
                                      std::lock_guard lock(self->mutex);
                                      self->counters.udp_incomplete_dropped = self->reassembler.dropped();
                                      self->counters.udp_malformed = self->reassembler.malformed();
                                    }
                                    self->read_udp();
                                  });
  }
  // Joins `group` (address:port) on the interface of the TCP connection; on the strand.
  Status join_multicast(const std::string& group) {
    // From the server: checked, never trusted to parse (a throw here would
    // leave the strand).
    const auto colon = group.rfind(':');
    boost::system::error_code ec;
    const auto address = net::ip::make_address_v4(group.substr(0, colon == std::string::npos ? 0 : colon), ec);
    unsigned port = 0;
    const char* digits = group.data() + (colon == std::string::npos ? group.size() : colon + 1);
    const auto parsed = std::from_chars(digits, group.data() + group.size(), port);
    if (ec || colon == std::string::npos || !address.is_multicast() || parsed.ec != std::errc() ||
        parsed.ptr != group.data() + group.size() || port == 0 || port > 65535) {
      return make_error("the server named a bad multicast group '" + group.substr(0, 64) + "'");
    }
    if (multicast_socket) return Ok{};  // one group per server
    const auto local = socket.tcp().local_endpoint(ec).address();
    udp::socket s(strand);
    s.open(udp::v4(), ec);
    if (!ec) s.set_option(net::socket_base::reuse_address(true), ec);
    if (!ec) s.bind(udp::endpoint(net::ip::address_v4::any(), static_cast<std::uint16_t>(port)), ec);
    if (!ec) s.set_option(net::socket_base::receive_buffer_size(4 << 20), ec);
    if (!ec) {
      s.set_option(local.is_v4() ? net::ip::multicast::join_group(address, local.to_v4())
                                 : net::ip::multicast::join_group(address),
                   ec);
    }
    if (ec) return make_error("cannot join multicast " + group + ": " + ec.message());
    multicast_socket.emplace(std::move(s));
    read_multicast();
    return Ok{};
  }
  void read_multicast() {
    multicast_socket->async_receive_from(
        net::buffer(multicast_buffer), multicast_sender,
        [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
          if (ec == net::error::operation_aborted || !self->open) return;
          // Only the server's UDP socket sends the group's frames.
          if (!ec && self->multicast_sender == self->server_udp) {
            if (auto msg = self->multicast_reassembler.add(std::string_view(self->multicast_buffer.data(), n))) {
              pb::ServerMessage m;
              if (m.ParseFromString(*msg) && m.has_frame()) {
                std::vector<std::uint32_t> ids;
                {
                  std::lock_guard lock(self->mutex);
                  for (const auto& [id, sub] : self->subs) {
                    if (sub->multicast && sub->stream_id == m.frame().stream_id()) ids.push_back(id);
                  }
                }
                for (const std::uint32_t id : ids) {
                  m.mutable_frame()->set_subscription_id(id);
                  self->on_message(m, true);
                }
              }
            }
          }
          self->read_multicast();
        });
  }
  void arm_heartbeat() {
    const auto interval = std::chrono::milliseconds(
        std::max<std::uint32_t>(10, std::min(hello.heartbeat_interval_ms, hello.idle_timeout_ms / 3)));
    heartbeat.expires_after(interval);
    heartbeat.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
      if (ec || !self->open) return;
      pb::ClientMessage m;
      m.mutable_heartbeat()->set_client_time_ns(static_cast<std::uint64_t>(now_ns()));
      self->send(wire::frame_message(m).value());  // a full queue already keeps the link busy
      self->arm_heartbeat();
    });
  }

  // A held end notice (Sub::ending) is given to on_end once every frame it
  // counts arrived, or (`now`) when its grace is over.
  void finish_ending(std::uint32_t id, const std::shared_ptr<Sub>& sub, bool now) {
    std::optional<SubscriptionEnd> end;
    {
      std::lock_guard lock(mutex);
      if (!sub->ending || (!now && sub->arrived < frames_to_come(*sub->ending))) return;
      end = std::move(sub->ending);
      sub->ending.reset();
      if (auto it = subs.find(id); it != subs.end() && it->second == sub) subs.erase(it);
      if (sub->ending_timer) sub->ending_timer->cancel();
    }
    if (sub->on_end) sub->on_end(*end);
  }

  void on_message(const pb::ServerMessage& m, bool via_udp) {
    if (m.has_frame()) {
      if (auto sub = deliver_frame(m.frame(), via_udp)) finish_ending(m.frame().subscription_id(), sub, false);
      return;
    }
    on_reply_or_push(m);
  }

  // Hands a frame to its subscription's on_frame (or drops and counts it);
  // the subscription it was for, or null.
  std::shared_ptr<Sub> deliver_frame(const pb::Frame& f, bool via_udp) {
    std::shared_ptr<Sub> sub;
    {
      std::lock_guard lock(mutex);
      (via_udp ? counters.frames_udp : counters.frames_tcp)++;
      if (auto it = subs.find(f.subscription_id()); it != subs.end()) {
        sub = it->second;
        ++sub->arrived;
        if (f.skeleton_version() != sub->skeleton_version) {
          ++counters.frames_other_skeleton;
          return sub;
        }
      } else if (subscribes_in_flight > 0) {
        if (early_frames.size() == kMaxEarlyFrames) early_frames.pop_front();
        pb::ServerMessage held;
        *held.mutable_frame() = f;
        early_frames.emplace_back(std::move(held), via_udp);
        (via_udp ? counters.frames_udp : counters.frames_tcp)--;  // counted when replayed
        return nullptr;
      }
    }
    if (!sub || !sub->on_frame) return sub;
    const std::int64_t received = now_ns();
    // Older than its bound (it waited in the kernel's buffers while this
    // client was not reading): dropped, counted.
    if (sub->max_age_ns > 0 && received + hello.clock_offset_ns - f.server_send_time_ns() > sub->max_age_ns) {
      std::lock_guard lock(mutex);
      ++counters.frames_stale;
      return sub;
    }
    auto decoded = wire::decode_frame(f);
    if (!decoded.ok()) {
      std::lock_guard lock(mutex);
      ++counters.frames_malformed;
      return sub;
    }
    ReceivedFrame r;
    static_cast<wire::FrameValues&>(r) = std::move(decoded).value();
    r.receive_time_ns = received;
    r.udp = via_udp;
    sub->on_frame(r);
    return sub;
  }

  void on_reply_or_push(const pb::ServerMessage& m) {
    if (m.request_id() != 0) {
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
      return;
    }
    if (m.has_subscription_ended()) {
      const std::uint32_t id = m.subscription_ended().subscription_id();
      SubscriptionEnd end = end_of(m.subscription_ended());
      std::shared_ptr<Sub> sub;
      bool held = false;
      {
        std::lock_guard lock(mutex);
        if (auto it = subs.find(id); it != subs.end() && !it->second->ending) {
          sub = it->second;
          if (sub->arrived < frames_to_come(end)) {
            // Frames it counts are still on their way (UDP): wait for them.
            sub->ending = std::move(end);
            sub->ending_timer = std::make_shared<net::steady_timer>(strand, kEndGrace);
            held = true;
          } else {
            subs.erase(it);
          }
        }
      }
      if (held) {
        sub->ending_timer->async_wait([self = shared_from_this(), id, sub](const boost::system::error_code& ec) {
          if (!ec) self->finish_ending(id, sub, true);
        });
      } else if (sub && sub->on_end) {
        sub->on_end(end);
      }
    } else if (m.has_skeleton_changed()) {
      const auto& c = m.skeleton_changed();
      std::shared_ptr<Sub> sub;
      {
        std::lock_guard lock(mutex);
        if (auto it = subs.find(c.subscription_id()); it != subs.end()) sub = it->second;
      }
      auto sk = wire::from_proto(c.skeleton());
      if (sub && sk.ok()) {
        std::lock_guard lock(mutex);
        sub->skeleton_version = c.skeleton_version();
      }
      if (sub && sub->on_skeleton && sk.ok()) {
        SkeletonChange change;
        change.subscription_id = c.subscription_id();
        change.view_id = c.view_id();
        change.skeleton_version = c.skeleton_version();
        change.skeleton = std::move(sk).value();
        change.rest = wire::rest_from_proto(c.skeleton());
        for (std::uint32_t j : c.joints()) change.joints.push_back(static_cast<int>(j));
        change.relative_to = c.relative_to();
        sub->on_skeleton(change);
      }
    } else if (m.has_udp_registered()) {
      std::lock_guard lock(mutex);
      udp_registered = true;
      udp_cv.notify_all();
    } else if (m.has_error()) {
      std::lock_guard lock(mutex);
      close_reason = std::string(wire::error_code_name(m.error().code())) + ": " + m.error().message();
    }
  }

  void fail(const std::string& reason) {
    if (!open.exchange(false)) return;
    boost::system::error_code ec;
    socket.tcp().close(ec);
    udp_socket.close(ec);
    if (multicast_socket) multicast_socket->close(ec);
    heartbeat.cancel();
    std::map<std::uint64_t, Pending> orphans;
    {
      std::lock_guard lock(mutex);
      if (close_reason.empty()) close_reason = reason;
      orphans.swap(pending);
      udp_cv.notify_all();
    }
    for (auto& [id, p] : orphans) p.promise.set_value(std::nullopt);
  }

  Result<pb::ServerMessage> call(pb::ClientMessage m, std::function<void(const pb::ServerMessage&)> on_reply = {}) {
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

  // The TLS handshake on the connected socket, within options.timeout: the
  // server's certificate must chain to the CA and name the server.
  Status start_tls(const std::string& where) {
    const auto& t = options.tls;
    const std::string name = t.server_name.empty() ? options.host : t.server_name;
    boost::system::error_code ec;
    tls_context.emplace(net::ssl::context::tls_client);
    auto& ctx = *tls_context;
    ctx.set_options(net::ssl::context::default_workarounds | net::ssl::context::no_sslv2 |
                    net::ssl::context::no_sslv3 | net::ssl::context::no_tlsv1 | net::ssl::context::no_tlsv1_1);
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
    ctx.set_verify_callback([check = net::ssl::host_name_verification(name), name_matched](
                                bool preverified, net::ssl::verify_context& v) {
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
      net::post(strand, [self = shared_from_this()] { boost::system::error_code e; self->socket.tcp().close(e); });
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

  // A reply of the expected kind, or the server's Error as an Error.
  Result<pb::ServerMessage> expect(pb::ClientMessage m, pb::ServerMessage::BodyCase expected,
                                   std::function<void(const pb::ServerMessage&)> on_reply = {}) {
    auto r = call(std::move(m), std::move(on_reply));
    if (!r.ok()) return r;
    if (r->has_error()) {
      return make_error(std::string(wire::error_code_name(r->error().code())) + ": " + r->error().message());
    }
    if (r->body_case() != expected) return make_error("unexpected reply from the server");
    return r;
  }
};

namespace {

Result<ViewState> to_view(Result<pb::ServerMessage> r) {
  if (!r.ok()) return r.error();
  const pb::ViewInfo& v = r->view();
  auto sk = wire::from_proto(v.skeleton());
  if (!sk.ok()) return make_error("the server sent an invalid skeleton: " + sk.error().message);
  ViewState s;
  s.id = v.view_id();
  s.motion = v.motion();
  s.skeleton_version = v.skeleton_version();
  s.skeleton = std::move(sk).value();
  s.rest = wire::rest_from_proto(v.skeleton());
  s.relative_to = v.relative_to();
  s.frame_count = v.frame_count();
  s.frame_time = v.frame_time();
  s.removed.assign(v.removed().begin(), v.removed().end());
  s.join_offset_spread = v.join_offset_spread();
  return s;
}

Status to_status(Result<pb::ServerMessage> r) {
  if (!r.ok()) return r.error();
  return Ok{};
}

}  // namespace

Result<std::unique_ptr<Client>> Client::connect(const ClientOptions& options) {
  std::unique_ptr<Client> c(new Client());
  c->impl_ = std::make_shared<Impl>(options.loop ? options.loop->impl_->loop : std::make_shared<Loop>());
  auto& d = *c->impl_;
  d.options = options;
  d.own_loop = options.loop == nullptr;
  boost::system::error_code ec;
  tcp::resolver resolver(d.io);
  auto endpoints = resolver.resolve(options.host, std::to_string(options.port), ec);
  if (ec) return make_error("cannot resolve " + options.host + ": " + ec.message());
  // Connect on the I/O thread so the timeout applies.
  std::promise<boost::system::error_code> connected;
  auto connected_future = connected.get_future();
  d.socket.tcp().open(endpoints.begin()->endpoint().protocol(), ec);
  if (options.receive_buffer > 0) {
    d.socket.tcp().set_option(net::socket_base::receive_buffer_size(options.receive_buffer), ec);
  }
  net::async_connect(d.socket.tcp(), endpoints,
                     [&connected](const boost::system::error_code& e, const tcp::endpoint&) { connected.set_value(e); });
  if (d.own_loop) {
    d.guard.emplace(d.io.get_executor());
    d.thread = std::thread([impl = c->impl_] { impl->io.run(); });
  }
  const std::string where = options.host + ":" + std::to_string(options.port);
  if (connected_future.wait_for(options.timeout) != std::future_status::ready) {
    net::post(d.strand, [impl = c->impl_] { boost::system::error_code e; impl->socket.tcp().close(e); });
    connected_future.wait();
    c->close();
    return make_error("cannot connect to " + where + ": timed out");
  }
  if (auto e = connected_future.get()) {
    c->close();
    return make_error("cannot connect to " + where + ": " + e.message());
  }
  d.socket.tcp().set_option(tcp::no_delay(true), ec);
  if (options.tls.enabled) {
    if (auto s = d.start_tls(where); !s.ok()) {
      c->close();
      return s.error();
    }
  }
  d.open = true;
  const auto remote = d.socket.tcp().remote_endpoint(ec);
  net::post(d.strand, [impl = c->impl_] { impl->read_prefix(); });

  pb::ClientMessage hello;
  hello.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  hello.mutable_hello()->set_client_name(options.client_name);
  hello.mutable_hello()->set_auth_token(options.auth_token);
  const std::int64_t hello_sent = now_ns();
  auto r = d.expect(hello, pb::ServerMessage::kHello);
  const std::int64_t hello_answered = now_ns();
  if (!r.ok()) {
    c->close();
    // A TLS server closes a plain client's connection without a word.
    const bool closed = r.error().message.find("closed the connection") != std::string::npos;
    return make_error("handshake with " + where + " failed: " + r.error().message +
                      (closed && !options.tls.enabled ? " (if the server speaks TLS, connect with TLS: --tls)" : ""));
  }
  d.hello = hello_of(r->hello());
  d.hello.tls = d.socket.tls();
  // The server read its clock about halfway through the round trip.
  if (r->hello().server_time_ns() != 0) {
    d.hello.clock_offset_ns = r->hello().server_time_ns() - (hello_sent + (hello_answered - hello_sent) / 2);
  }
  d.server_udp = udp::endpoint(remote.address(), d.hello.udp_port);
  d.udp_socket.open(remote.address().is_v4() ? udp::v4() : udp::v6(), ec);
  if (!ec) d.udp_socket.bind(udp::endpoint(remote.address().is_loopback() ? remote.address() : net::ip::address(), 0), ec);
  // A deep receive buffer rides out scheduling stalls of the I/O thread (the
  // kernel caps it at net.core.rmem_max).
  if (!ec) d.udp_socket.set_option(net::socket_base::receive_buffer_size(4 << 20), ec);
  net::post(d.strand, [impl = c->impl_] {
    if (impl->udp_socket.is_open()) impl->read_udp();
    impl->arm_heartbeat();
  });
  return c;
}

Client::~Client() { close(); }

void Client::close() {
  // A second close() does nothing: with its own loop, once the I/O thread is
  // gone (joined, or detached and ending) nothing would run a posted handler,
  // and one left queued in io would keep Impl, which owns io, alive for ever.
  if (!impl_ || impl_->closed.exchange(true)) return;
  if (!impl_->own_loop) {
    // A shared loop: the connection is failed on its strand; unless called
    // from one of the loop's threads (a callback), wait for that, so no
    // callback runs after close() returns.
    auto done = std::make_shared<std::promise<void>>();
    auto finished = done->get_future();
    net::post(impl_->strand, [impl = impl_, done] {
      impl->fail("closed by the client");
      done->set_value();
    });
    if (!impl_->loop->runs_here()) finished.wait();
    return;
  }
  if (!impl_->thread.joinable()) return;
  net::post(impl_->strand, [impl = impl_] {
    impl->fail("closed by the client");
    impl->guard.reset();
  });
  if (impl_->thread.joinable()) {
    if (impl_->thread.get_id() == std::this_thread::get_id()) {
      impl_->thread.detach();  // close() from a callback: the thread ends by itself
    } else {
      impl_->thread.join();
    }
  }
}

const ServerHello& Client::hello() const { return impl_->hello; }
bool Client::connected() const { return impl_->open; }

ClientCounters Client::counters() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->counters;
}

Result<std::string> Client::request_raw(std::string_view client_message) {
  pb::ClientMessage m;
  if (!m.ParseFromArray(client_message.data(), static_cast<int>(client_message.size()))) {
    return make_error("request_raw: the bytes are not a gmr.stream.v1.ClientMessage");
  }
  auto r = impl_->call(std::move(m));
  if (!r.ok()) return r.error();
  return r->SerializeAsString();
}

Result<std::vector<MotionInfo>> Client::list_motions() {
  pb::ClientMessage m;
  m.mutable_list_motions();
  auto r = impl_->expect(m, pb::ServerMessage::kMotions);
  if (!r.ok()) return r.error();
  std::vector<MotionInfo> out;
  for (const auto& i : r->motions().motions()) {
    out.push_back(MotionInfo{i.name(), i.joint_count(), i.frame_count(), i.frame_time(), i.source(), i.metres_per_unit()});
  }
  return out;
}

Result<Skeleton> Client::skeleton(const std::string& motion) {
  pb::ClientMessage m;
  m.mutable_get_skeleton()->set_motion(motion);
  auto r = impl_->expect(m, pb::ServerMessage::kSkeleton);
  if (!r.ok()) return r.error();
  return wire::from_proto(r->skeleton().skeleton());
}

Result<RestPose> Client::rest_pose(const std::string& motion, const Conventions& conventions) {
  pb::ClientMessage m;
  m.mutable_get_skeleton()->set_motion(motion);
  to_proto(conventions, *m.mutable_get_skeleton()->mutable_conventions());
  auto r = impl_->expect(m, pb::ServerMessage::kSkeleton);
  if (!r.ok()) return r.error();
  return wire::rest_from_proto(r->skeleton().skeleton());
}

Result<ViewState> Client::create_view(const std::string& motion) {
  pb::ClientMessage m;
  m.mutable_create_view()->set_motion(motion);
  return to_view(impl_->expect(m, pb::ServerMessage::kView));
}

Status Client::close_view(std::uint32_t view) {
  pb::ClientMessage m;
  m.mutable_close_view()->set_view_id(view);
  return to_status(impl_->expect(m, pb::ServerMessage::kAck));
}

Result<ViewState> Client::shift_root(std::uint32_t view, const std::string& joint) {
  pb::ClientMessage m;
  m.mutable_shift_root()->set_view_id(view);
  m.mutable_shift_root()->set_joint(joint);
  return to_view(impl_->expect(m, pb::ServerMessage::kView));
}

Result<ViewState> Client::split(std::uint32_t view, const std::string& joint) {
  pb::ClientMessage m;
  m.mutable_split()->set_view_id(view);
  m.mutable_split()->set_joint(joint);
  return to_view(impl_->expect(m, pb::ServerMessage::kView));
}

Result<ViewState> Client::join(std::uint32_t view, const std::string& root) {
  pb::ClientMessage m;
  m.mutable_join()->set_view_id(view);
  m.mutable_join()->set_root(root);
  return to_view(impl_->expect(m, pb::ServerMessage::kView));
}

Result<ViewState> Client::set_roots(std::uint32_t view, const std::vector<std::string>& roots) {
  pb::ClientMessage m;
  m.mutable_set_roots()->set_view_id(view);
  for (const auto& r : roots) m.mutable_set_roots()->add_roots(r);
  return to_view(impl_->expect(m, pb::ServerMessage::kView));
}

Result<ViewState> Client::strip_dummies(std::uint32_t view) {
  pb::ClientMessage m;
  m.mutable_strip_dummies()->set_view_id(view);
  return to_view(impl_->expect(m, pb::ServerMessage::kView));
}

Result<ViewState> Client::set_coordinates(std::uint32_t view, const std::string& relative_to) {
  pb::ClientMessage m;
  m.mutable_set_coordinates()->set_view_id(view);
  m.mutable_set_coordinates()->set_relative_to(relative_to);
  return to_view(impl_->expect(m, pb::ServerMessage::kView));
}

Result<QueryResult> Client::query(std::uint32_t view, std::uint32_t begin, std::uint32_t end, bool orientations,
                                  const std::vector<std::string>& joints, const Conventions& conventions) {
  return query(view, begin, end, QueryOptions{orientations, false, joints, conventions});
}

Result<QueryResult> Client::query(std::uint32_t view, std::uint32_t begin, std::uint32_t end, const QueryOptions& o) {
  pb::ClientMessage m;
  auto* q = m.mutable_query_frames();
  q->set_view_id(view);
  q->set_begin(begin);
  q->set_end(end);
  q->set_orientations(o.orientations);
  q->set_local_transforms(o.local_transforms);
  for (const auto& j : o.joints) q->add_joints(j);
  to_proto(o.conventions, *q->mutable_conventions());
  auto r = impl_->expect(m, pb::ServerMessage::kFrames);
  if (!r.ok()) return r.error();
  auto b = wire::decode_block(r->frames());
  if (!b.ok()) return make_error(ErrorKind::kInvalidData, "the server sent a bad frame block: " + b.error().message);
  QueryResult out;
  out.skeleton_version = b->skeleton_version;
  out.begin = b->begin;
  out.end = b->end;
  out.joints = std::move(b->joints);
  out.positions = std::move(b->positions);
  out.orientations = std::move(b->orientations);
  out.local_rotations = std::move(b->local_rotations);
  out.local_translations = std::move(b->local_translations);
  return out;
}

Status Client::register_udp() {
  auto& d = *impl_;
  if (!d.udp_socket.is_open() || d.hello.udp_port == 0) return make_error("the server offers no UDP");
  wire::UdpToken token;
  std::memcpy(token.data(), d.hello.udp_token.data(), token.size());
  const std::string datagram = wire::make_register_datagram(token);
  const auto deadline = std::chrono::steady_clock::now() + d.options.timeout;
  std::unique_lock lock(d.mutex);
  // Registration datagrams can be lost like any other: resend until the
  // server confirms over TCP.
  while (!d.udp_registered && d.open) {
    lock.unlock();
    net::post(d.strand, [impl = impl_, datagram] {
      boost::system::error_code ec;
      impl->udp_socket.send_to(net::buffer(datagram), impl->server_udp, 0, ec);
    });
    lock.lock();
    if (std::chrono::steady_clock::now() >= deadline) break;
    d.udp_cv.wait_for(lock, std::chrono::milliseconds(50));
  }
  if (d.udp_registered) return Ok{};
  return make_error(d.open ? "the server did not confirm the UDP registration in time" : "not connected: " + d.close_reason);
}

Result<SubscriptionInfo> Client::subscribe(std::uint32_t view, const SubscribeOptions& o, FrameCallback on_frame,
                                           EndCallback on_end, SkeletonCallback on_skeleton) {
  if (o.udp && !o.multicast) {
    if (auto s = register_udp(); !s.ok()) return s.error();
  }
  pb::ClientMessage m;
  auto* s = m.mutable_subscribe();
  s->set_view_id(view);
  s->set_start_frame(o.start_frame);
  s->set_end_frame(o.end_frame);
  s->set_loop(o.loop);
  s->set_speed(o.speed);
  s->set_rate_hz(o.rate_hz);
  s->set_skip_repeats(o.skip_repeats);
  s->set_orientations(o.orientations);
  s->set_local_transforms(o.local_transforms);
  for (const auto& j : o.joints) s->add_joints(j);
  s->set_transport(o.multicast ? pb::TRANSPORT_MULTICAST : o.udp ? pb::TRANSPORT_UDP : pb::TRANSPORT_TCP);
  s->set_precision(o.float64 ? pb::PRECISION_FLOAT64 : pb::PRECISION_FLOAT32);
  s->set_shared(o.shared);
  to_proto(o.conventions, *s->mutable_conventions());
  s->set_max_frames(o.max_frames);
  // Zero: no bound, which the wire says with the largest (0 there is the server's default).
  const auto staleness_ms = o.max_staleness.count() <= 0 ? std::numeric_limits<std::uint32_t>::max()
                                                          : static_cast<std::uint32_t>(std::min<std::int64_t>(
                                                                o.max_staleness.count(), std::numeric_limits<std::uint32_t>::max()));
  s->set_max_staleness_ms(staleness_ms);
  auto sub = std::make_shared<Impl::Sub>(Impl::Sub{std::move(on_frame), std::move(on_end), std::move(on_skeleton),
                                                   o.max_staleness.count() > 0 ? std::int64_t{o.max_staleness.count()} * 1000000 : 0});
  // Registered on the I/O thread as the reply is read, before any frame.
  {
    std::lock_guard lock(impl_->mutex);
    ++impl_->subscribes_in_flight;
  }
  auto replied = std::make_shared<std::atomic<bool>>(false);
  auto r = impl_->expect(m, pb::ServerMessage::kSubscribed, [impl = impl_.get(), sub, replied](const pb::ServerMessage& reply) {
    std::deque<std::pair<pb::ServerMessage, bool>> replay;
    {
      std::lock_guard lock(impl->mutex);
      *replied = true;
      --impl->subscribes_in_flight;
      if (reply.has_subscribed()) {
        sub->stream_id = reply.subscribed().stream_id();
        sub->skeleton_version = reply.subscribed().skeleton_version();
        sub->multicast = !reply.subscribed().multicast_group().empty();
        impl->subs[reply.subscribed().subscription_id()] = sub;
      }
      if (impl->subscribes_in_flight == 0) replay.swap(impl->early_frames);
    }
    for (auto& [frame, via_udp] : replay) impl->on_message(frame, via_udp);
  });
  {
    std::lock_guard lock(impl_->mutex);
    if (!*replied) --impl_->subscribes_in_flight;  // timed out or lost: no reply will come
  }
  if (!r.ok()) return r.error();
  const auto& sr = r->subscribed();
  SubscriptionInfo info;
  info.id = sr.subscription_id();
  info.view_id = sr.view_id();
  info.skeleton_version = sr.skeleton_version();
  info.joints.assign(sr.joints().begin(), sr.joints().end());
  info.rate_hz = sr.rate_hz();
  info.stream_id = sr.stream_id();
  info.joined_running = sr.joined_running();
  if (sr.has_skeleton()) {  // older servers send none
    auto sk = wire::from_proto(sr.skeleton());
    if (!sk.ok()) return make_error("the server sent an invalid skeleton: " + sk.error().message);
    info.skeleton = std::move(sk).value();
    info.rest = wire::rest_from_proto(sr.skeleton());
  }
  info.relative_to = sr.relative_to();
  info.multicast_group = sr.multicast_group();
  if (!info.multicast_group.empty()) {
    // Joined on the strand, as every socket of this client is used.
    auto joined = std::make_shared<std::promise<Status>>();
    auto done = joined->get_future();
    net::post(impl_->strand, [impl = impl_, joined, group = info.multicast_group] {
      joined->set_value(impl->join_multicast(group));
    });
    if (Status joined_status = done.get(); !joined_status.ok()) {
      (void)unsubscribe(info.id);
      return joined_status.error();
    }
  }
  return info;
}

Status Client::unsubscribe(std::uint32_t subscription) {
  pb::ClientMessage m;
  m.mutable_unsubscribe()->set_subscription_id(subscription);
  auto r = impl_->expect(m, pb::ServerMessage::kAck);
  std::lock_guard lock(impl_->mutex);
  impl_->subs.erase(subscription);
  return to_status(std::move(r));
}

Status Client::pause(std::uint32_t subscription) {
  pb::ClientMessage m;
  m.mutable_pause()->set_subscription_id(subscription);
  return to_status(impl_->expect(m, pb::ServerMessage::kAck));
}

Status Client::resume(std::uint32_t subscription) {
  pb::ClientMessage m;
  m.mutable_resume()->set_subscription_id(subscription);
  return to_status(impl_->expect(m, pb::ServerMessage::kAck));
}

Status Client::seek(std::uint32_t subscription, std::uint32_t frame) {
  pb::ClientMessage m;
  m.mutable_seek()->set_subscription_id(subscription);
  m.mutable_seek()->set_frame(frame);
  return to_status(impl_->expect(m, pb::ServerMessage::kAck));
}

Result<ServerCounters> Client::stats() {
  pb::ClientMessage m;
  m.mutable_get_stats();
  auto r = impl_->expect(m, pb::ServerMessage::kStats);
  if (!r.ok()) return r.error();
  const pb::Stats& s = r->stats();
  ServerCounters c;
  c.connections = s.connections();
  c.streams = s.streams();
  c.frames_computed = s.frames_computed();
  c.frames_computed_float = s.frames_computed_float();
  c.frames_encoded = s.frames_encoded();
  c.frames_sent = s.frames_sent();
  c.frames_dropped = s.frames_dropped();
  c.frames_skipped = s.frames_skipped();
  c.frames_skipped_total = s.frames_skipped_total();
  c.queued_bytes = s.queued_bytes();
  c.max_queued_bytes = s.max_queued_bytes();
  c.committed_frames_per_second = s.committed_frames_per_second();
  c.send_budget = s.send_budget();
  c.subscriptions_refused = s.subscriptions_refused();
  c.live_sources = s.live_sources();
  c.live_frames_received = s.live_frames_received();
  c.live_frames_refused = s.live_frames_refused();
  c.multicast_frames_sent = s.multicast_frames_sent();
  c.frames_sent_total = s.frames_sent_total();
  c.frames_dropped_total = s.frames_dropped_total();
  c.io_threads = s.io_threads();
  c.io_thread = s.io_thread();
  return c;
}

Result<Publication> Client::publish(const Skeleton& skeleton, const PublishOptions& options) {
  pb::ClientMessage m;
  auto* p = m.mutable_publish();
  p->set_name(options.name);
  wire::to_proto(skeleton, *p->mutable_skeleton());
  p->set_frame_time(options.frame_time);
  p->set_metres_per_unit(options.metres_per_unit);
  p->set_record(options.record);
  auto r = impl_->expect(m, pb::ServerMessage::kPublished);
  if (!r.ok()) return r.error();
  return Publication{r->published().publication_id(), r->published().motion(), r->published().recording()};
}

Status Client::publish_frame(std::uint32_t publication, std::span<const double> values) {
  pb::ClientMessage m;
  m.set_request_id(impl_->next_request++);  // an Error for it names this id
  auto* f = m.mutable_publish_frame();
  f->set_publication_id(publication);
  f->mutable_values()->Add(values.begin(), values.end());
  auto framed = wire::frame_message(m, impl_->hello.max_message_bytes != 0 ? impl_->hello.max_message_bytes : 1u << 30);
  if (!framed.ok()) return framed.error();
  {
    std::lock_guard lock(impl_->mutex);
    if (!impl_->open) return make_error("not connected: " + impl_->close_reason);
  }
  if (!impl_->send(std::move(framed).value())) {
    return make_error(ErrorKind::kResourceExhausted, "write queue full: the server is not reading this client's frames");
  }
  return Ok{};
}

Status Client::unpublish(std::uint32_t publication) {
  pb::ClientMessage m;
  m.mutable_unpublish()->set_publication_id(publication);
  return to_status(impl_->expect(m, pb::ServerMessage::kAck));
}

std::vector<std::string> Client::take_errors() {
  std::lock_guard lock(impl_->mutex);
  std::vector<std::string> out(impl_->async_errors.begin(), impl_->async_errors.end());
  impl_->async_errors.clear();
  return out;
}

}  // namespace gmr::client
