#include "gmr/server/server.h"

#include <spdlog/spdlog.h>

#include <boost/asio.hpp>
#include <chrono>
#include <cmath>
#include <deque>
#include <future>
#include <map>
#include <random>
#include <stdexcept>
#include <thread>
#include <unordered_map>

#include "gmr/server/view.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/frame_encoding.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"

namespace gmr::server {

namespace net = boost::asio;
namespace pb = ::gmr::stream::v1;
using tcp = net::ip::tcp;
using udp = net::ip::udp;
using Clock = std::chrono::steady_clock;
// How far a stream may fall behind its schedule and still catch up frame by frame.
constexpr Clock::duration kMaxCatchUp = std::chrono::milliseconds(250);
// Stream parameters: beyond these the schedule arithmetic loses meaning (or
// one stream could monopolise the I/O thread).
constexpr double kMinSpeed = 1e-3, kMaxSpeed = 1000.0;
constexpr double kMinRateHz = 1e-2, kMaxRateHz = 10000.0;

class Session;
class Stream;

// Everything the server shares between sessions. Touched only on the I/O thread.
struct Server::Impl {
  ServerConfig cfg;
  std::vector<LibraryEntry> library;
  std::map<std::string, std::size_t, std::less<>> by_name;

  net::io_context io;
  tcp::acceptor acceptor{io};
  udp::socket udp_socket{io};
  std::thread thread;
  std::uint16_t tcp_port = 0;
  std::uint16_t udp_port = 0;
  bool started = false;
  bool stopping = false;
  std::promise<void> stopped;
  std::shared_future<void> stopped_future = stopped.get_future().share();

  std::uint64_t next_session_id = 1;
  std::map<std::uint64_t, std::weak_ptr<Session>> sessions;
  std::unordered_map<std::uint64_t, std::weak_ptr<Session>> tokens;
  std::map<std::string, std::weak_ptr<Stream>> shared_streams;
  std::map<std::uint64_t, std::weak_ptr<Stream>> streams;
  std::uint64_t next_stream_id = 1;
  std::mt19937_64 rng{std::random_device{}()};

  std::uint64_t frames_computed = 0;
  std::uint64_t frames_encoded = 0;
  std::uint64_t udp_rejected = 0;
  std::uint64_t connections_refused = 0;

  std::unique_ptr<net::steady_timer> grace_timer;  // while stopping
  std::array<char, 2048> udp_buffer{};
  udp::endpoint udp_sender;

  void accept_loop();
  void udp_loop();
  // Forgets streams no subscription holds any more (the maps keep weak pointers).
  void prune_streams() {
    std::erase_if(streams, [](const auto& kv) { return kv.second.expired(); });
    std::erase_if(shared_streams, [](const auto& kv) { return kv.second.expired(); });
  }
  void begin_stop();
  ServerStats snapshot() const;
};

namespace {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

pb::ServerMessage error_message(std::uint64_t request_id, pb::ErrorCode code, std::string text) {
  pb::ServerMessage m;
  m.set_request_id(request_id);
  m.mutable_error()->set_code(code);
  m.mutable_error()->set_message(std::move(text));
  return m;
}

struct RequestError {
  pb::ErrorCode code;
  std::string message;
};

}  // namespace

// ---------------------------------------------------------------------------
// Stream: one schedule, one content; one FK and one encoding per tick, fanned
// out to every target. Frame k of the schedule is due at base_time + k/rate.
class Stream : public std::enable_shared_from_this<Stream> {
 public:
  struct Schedule {
    std::uint32_t start = 0;
    std::uint32_t end = 0;  // exclusive
    bool loop = false;
    double speed = 1.0;
    double rate = 0.0;
    bool skip_repeats = false;
  };
  struct Target {
    std::weak_ptr<Session> session;
    std::uint32_t subscription_id = 0;
    std::uint32_t view_id = 0;
    bool udp = false;
    std::uint64_t sent = 0;
    std::uint64_t max_frames = 0;
  };

  Stream(Server::Impl& impl, std::uint64_t id, std::shared_ptr<const ViewContent> content, std::vector<int> joints,
         bool orientations, bool float64, Schedule schedule)
      : impl_(impl), id_(id), content_(std::move(content)), joints_(std::move(joints)), orientations_(orientations),
        float64_(float64), schedule_(schedule), timer_(impl.io) {}

  std::uint64_t id() const { return id_; }
  std::string key;  // non-empty while it can be joined by a shared subscription
  const std::vector<int>& joints() const { return joints_; }
  const Schedule& schedule() const { return schedule_; }
  bool paused() const { return paused_; }
  std::vector<Target>& targets() { return targets_; }

  void start() {
    rebase(Clock::now(), 0.0);
    arm();
  }
  void pause() {
    if (paused_) return;
    paused_ = true;
    pause_pos_ = position(tick_);
    timer_.cancel();
  }
  void resume() {
    if (!paused_) return;
    paused_ = false;
    rebase(Clock::now(), pause_pos_);
    arm();
  }
  void seek(std::uint32_t frame) {
    const double pos = static_cast<double>(frame - schedule_.start);
    last_frame_ = -1;
    if (paused_) {
      pause_pos_ = pos;
      return;
    }
    timer_.cancel();
    rebase(Clock::now(), pos);
    arm();
  }
  void set_content(std::shared_ptr<const ViewContent> content, std::vector<int> joints) {
    content_ = std::move(content);
    joints_ = std::move(joints);
    last_frame_ = -1;
  }
  // A copy of this stream's content and position for one target leaving it.
  std::shared_ptr<Stream> clone(std::uint64_t id) const {
    auto s = std::make_shared<Stream>(impl_, id, content_, joints_, orientations_, float64_, schedule_);
    s->sequence_ = sequence_;  // the subscriber sees no gap or restart
    s->last_frame_ = last_frame_;
    s->paused_ = paused_;
    const double pos = paused_ ? pause_pos_ : position(tick_);
    s->pause_pos_ = pos;
    if (!paused_) {
      s->rebase(Clock::now(), pos);
      s->arm();
    }
    return s;
  }
  void stop() { timer_.cancel(); }

 private:
  double step() const { return schedule_.speed / (schedule_.rate * content_->motion->frame_time); }
  double position(std::uint64_t tick) const { return base_pos_ + static_cast<double>(tick - base_tick_) * step(); }
  std::chrono::steady_clock::duration period() const {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / schedule_.rate));
  }
  void rebase(Clock::time_point now, double pos) {
    base_time_ = now;
    base_pos_ = pos;
    base_tick_ = tick_;
  }
  Clock::time_point due(std::uint64_t tick) const {
    return base_time_ + std::chrono::duration_cast<Clock::duration>(
                            std::chrono::duration<double>(static_cast<double>(tick - base_tick_) / schedule_.rate));
  }
  void arm() {
    timer_.expires_at(due(tick_));
    timer_.async_wait([weak = weak_from_this()](const boost::system::error_code& ec) {
      if (ec) return;
      if (auto self = weak.lock()) self->on_tick();
    });
  }
  void on_tick();

  Server::Impl& impl_;
  std::uint64_t id_;
  std::shared_ptr<const ViewContent> content_;
  std::vector<int> joints_;
  bool orientations_;
  bool float64_;
  Schedule schedule_;
  net::steady_timer timer_;
  std::vector<Target> targets_;

  Clock::time_point base_time_{};
  std::uint64_t base_tick_ = 0;
  double base_pos_ = 0.0;
  std::uint64_t tick_ = 0;
  bool paused_ = false;
  double pause_pos_ = 0.0;
  std::int64_t last_frame_ = -1;
  std::uint64_t sequence_ = 0;

  std::vector<Eigen::Vector3d> all_positions_;
  std::vector<Eigen::Matrix3d> all_orientations_;
  std::vector<Eigen::Vector3d> positions_;
  std::vector<Eigen::Quaterniond> quaternions_;
};

// ---------------------------------------------------------------------------
// Session: one TCP connection, its views and subscriptions, and its bounded
// outgoing queue (replies in order; frames latest-wins per subscription).
class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(Server::Impl& impl, tcp::socket socket, std::uint64_t id)
      : impl_(impl), socket_(std::move(socket)), id_(id), watchdog_(impl.io), read_gate_(impl.io) {
    boost::system::error_code ec;
    auto ep = socket_.remote_endpoint(ec);
    peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
    do {
      token_ = impl_.rng();
    } while (token_ == 0 || impl_.tokens.count(token_));
  }

  std::uint64_t id() const { return id_; }
  bool stopped() const { return stopped_; }

  void start() {
    impl_.tokens[token_] = weak_from_this();
    socket_.set_option(tcp::no_delay(true));
    if (impl_.cfg.socket_send_buffer > 0) {
      boost::system::error_code ec;
      socket_.set_option(net::socket_base::send_buffer_size(impl_.cfg.socket_send_buffer), ec);
    }
    last_read_ = last_write_ = Clock::now();
    spdlog::info("conn {}: connected from {}", id_, peer_);
    net::co_spawn(impl_.io, read_loop(shared_from_this()), net::detached);
    arm_watchdog();
  }

  // Ends the connection: streams forget it, the socket closes. Idempotent.
  void stop(const std::string& reason);
  // Graceful: finish writing the replies queued, then stop.
  void finish() {
    close_after_flush_ = true;
    pending_frames_.clear();
    subs_.clear();
    flush();
  }

  void send(const pb::ServerMessage& m);
  // A frame of subscription `sub` (latest wins over one not yet written).
  void push_frame(std::uint32_t sub, std::uint32_t view_id, std::uint64_t stream_id,
                  const std::shared_ptr<const std::string>& body, bool via_udp);
  // The stream ended this subscription (end of motion or max_frames).
  void subscription_ended(std::uint32_t sub, std::uint64_t sent, const std::string& reason);
  void udp_registered(const udp::endpoint& ep);

  SessionStats stats() const {
    SessionStats s;
    s.id = id_;
    s.frames_sent = frames_sent_;
    s.frames_dropped = frames_dropped_;
    s.queued_bytes = queued_bytes();
    s.max_queued_bytes = max_queued_bytes_;
    s.udp_registered = udp_endpoint_.has_value();
    return s;
  }

 private:
  struct Subscription {
    std::uint32_t id = 0;
    std::uint32_t view_id = 0;
    std::shared_ptr<Stream> stream;
    bool udp = false;
    std::vector<std::string> joint_names;  // empty: every joint
    std::uint64_t dropped = 0;
  };
  struct PendingFrame {
    std::string head;
    std::shared_ptr<const std::string> body;
  };

  net::awaitable<void> read_loop(std::shared_ptr<Session> self);
  void handle(const std::string& bytes);
  pb::ServerMessage dispatch(const pb::ClientMessage& req);
  void flush();
  void arm_watchdog();
  std::uint64_t queued_bytes() const {
    std::uint64_t n = reply_bytes_ + in_flight_bytes_;
    for (const auto& [id, f] : pending_frames_) n += f.head.size() + f.body->size();
    return n;
  }
  void note_queue() { max_queued_bytes_ = std::max(max_queued_bytes_, queued_bytes()); }

  View& view(std::uint32_t id);
  Subscription& subscription(std::uint32_t id);
  pb::ViewInfo view_info(const View& v) const;
  void view_changed(View& v);
  std::shared_ptr<Stream> detach(Subscription& sub);
  void drop_subscription(std::uint32_t id);
  Result<std::vector<int>> resolve_joints(const View& v, const std::vector<std::string>& names) const;

  pb::ServerMessage subscribe(const pb::Subscribe& r);
  pb::ServerMessage query(const pb::QueryFrames& r);

  Server::Impl& impl_;
  tcp::socket socket_;
  std::uint64_t id_;
  std::uint64_t token_ = 0;
  std::string peer_;
  bool handshaked_ = false;
  bool stopped_ = false;
  bool close_after_flush_ = false;

  std::map<std::uint32_t, std::unique_ptr<View>> views_;
  std::uint32_t next_view_ = 1;
  std::map<std::uint32_t, Subscription> subs_;
  std::uint32_t next_sub_ = 1;

  std::deque<std::shared_ptr<const std::string>> replies_;
  std::uint64_t reply_bytes_ = 0;
  std::map<std::uint32_t, PendingFrame> pending_frames_;
  bool writing_ = false;
  std::uint64_t in_flight_bytes_ = 0;
  std::uint64_t in_flight_reply_bytes_ = 0;
  std::vector<std::shared_ptr<const std::string>> hold_;
  std::vector<std::string> hold_heads_;
  Clock::time_point write_started_{}, last_read_{}, last_write_{};
  net::steady_timer watchdog_;
  net::steady_timer read_gate_;

  std::optional<udp::endpoint> udp_endpoint_;
  std::size_t udp_in_flight_ = 0;
  std::uint32_t udp_message_id_ = 0;

  std::uint64_t frames_sent_ = 0;
  std::uint64_t frames_dropped_ = 0;
  std::uint64_t max_queued_bytes_ = 0;
};

void Stream::on_tick() {
  if (paused_ || targets_.empty()) return;
  const Motion& m = *content_->motion;
  const double pos = position(tick_);
  const double length = static_cast<double>(schedule_.end - schedule_.start);
  std::vector<std::pair<std::weak_ptr<Session>, std::uint32_t>> ended;
  bool finished = false;
  double p = pos;
  if (schedule_.loop) {
    p = std::fmod(pos, length);
    if (p < 0) p += length;
  } else if (pos >= length - 1e-9) {
    finished = true;
  }
  if (!finished) {
    const auto offset = std::min<std::uint64_t>(static_cast<std::uint64_t>(std::floor(p + 1e-9)),
                                                static_cast<std::uint64_t>(length) - 1);
    const std::uint64_t frame = schedule_.start + offset;
    if (!(schedule_.skip_repeats && static_cast<std::int64_t>(frame) == last_frame_)) {
      last_frame_ = static_cast<std::int64_t>(frame);
      const std::size_t n = m.skeleton.size();
      all_positions_.resize(n);
      all_orientations_.resize(orientations_ ? n : 0);
      compute_view_frame(*content_, frame, all_positions_, all_orientations_);
      ++impl_.frames_computed;
      positions_.clear();
      quaternions_.clear();
      for (int j : joints_) {
        positions_.push_back(all_positions_[static_cast<std::size_t>(j)]);
        if (orientations_) quaternions_.emplace_back(all_orientations_[static_cast<std::size_t>(j)]);
      }
      wire::FrameContent c;
      c.skeleton_version = content_->skeleton_version;
      c.frame_index = frame;
      c.motion_time = static_cast<double>(frame) * m.frame_time;
      c.sequence = sequence_++;
      c.server_send_time_ns = now_ns();
      c.positions = positions_;
      c.orientations = quaternions_;
      c.float64 = float64_;
      auto body = std::make_shared<const std::string>(wire::encode_frame_body(c));
      ++impl_.frames_encoded;
      // Copy the targets first: a session may end a subscription re-entrantly.
      auto targets = targets_;
      for (auto& t : targets) {
        auto s = t.session.lock();
        if (!s || s->stopped()) continue;
        s->push_frame(t.subscription_id, t.view_id, id_, body, t.udp);
      }
      for (auto& t : targets_) {
        ++t.sent;
        if (t.max_frames != 0 && t.sent >= t.max_frames) ended.emplace_back(t.session, t.subscription_id);
      }
    }
  } else {
    for (auto& t : targets_) ended.emplace_back(t.session, t.subscription_id);
  }
  ++tick_;
  // Drift-free: the next tick is due at base + k/rate, so a late tick is
  // followed by the ones it delayed (no frame lost to scheduling jitter).
  // Only when the server fell far behind (a stall) does playback jump to the
  // tick due now rather than burst through the backlog.
  const auto now = Clock::now();
  if (due(tick_) + std::max<Clock::duration>(period(), kMaxCatchUp) < now) {
    const double behind = std::chrono::duration<double>(now - base_time_).count() * schedule_.rate;
    tick_ = std::max(tick_, base_tick_ + static_cast<std::uint64_t>(behind));
  }
  auto self = shared_from_this();  // sessions may drop the last reference below
  for (auto& [weak, sub] : ended) {
    const auto it = std::find_if(targets_.begin(), targets_.end(),
                                 [&](const Target& t) { return t.subscription_id == sub && !t.session.owner_before(weak) && !weak.owner_before(t.session); });
    const std::uint64_t sent = it != targets_.end() ? it->sent : 0;
    if (auto s = weak.lock()) s->subscription_ended(sub, sent, finished ? "end of motion" : "max_frames reached");
  }
  std::erase_if(targets_, [](const Target& t) { return t.session.expired(); });
  if (!targets_.empty() && !finished) arm();
}

// ---------------------------------------------------------------------------

void Session::stop(const std::string& reason) {
  if (stopped_) return;
  stopped_ = true;
  spdlog::info("conn {}: closed: {} (frames sent {}, dropped {})", id_, reason, frames_sent_, frames_dropped_);
  for (auto& [id, sub] : subs_) {
    std::erase_if(sub.stream->targets(), [&](const Stream::Target& t) { return t.subscription_id == id && t.session.lock().get() == this; });
  }
  subs_.clear();
  views_.clear();
  pending_frames_.clear();
  replies_.clear();
  reply_bytes_ = 0;
  impl_.tokens.erase(token_);
  boost::system::error_code ec;
  socket_.shutdown(tcp::socket::shutdown_both, ec);
  socket_.close(ec);
  watchdog_.cancel();
  read_gate_.cancel();
  impl_.sessions.erase(id_);
  if (impl_.stopping && impl_.sessions.empty() && impl_.grace_timer) impl_.grace_timer->cancel();
}

void Session::send(const pb::ServerMessage& m) {
  if (stopped_) return;
  auto bytes = wire::frame_message(m, impl_.cfg.max_message_bytes);
  if (!bytes.ok()) {
    bytes = wire::frame_message(error_message(m.request_id(), pb::ERROR_CODE_INTERNAL,
                                              "reply too large: " + bytes.error().message));
  }
  reply_bytes_ += bytes->size();
  replies_.push_back(std::make_shared<const std::string>(std::move(bytes).value()));
  note_queue();
  flush();
}

void Session::push_frame(std::uint32_t sub, std::uint32_t view_id, std::uint64_t stream_id,
                         const std::shared_ptr<const std::string>& body, bool via_udp) {
  if (stopped_ || close_after_flush_) return;
  auto it = subs_.find(sub);
  if (it == subs_.end()) return;
  if (via_udp) {
    if (!udp_endpoint_) {
      ++frames_dropped_;
      ++it->second.dropped;
      return;
    }
    auto message = wire::frame_message_for(view_id, sub, stream_id, *body);
    auto datagrams = wire::fragment_message(udp_message_id_++, message);
    if (udp_in_flight_ + datagrams.size() > impl_.cfg.max_udp_datagrams_in_flight) {
      ++frames_dropped_;
      ++it->second.dropped;
      return;
    }
    for (auto& d : datagrams) {
      auto held = std::make_shared<const std::string>(std::move(d));
      ++udp_in_flight_;
      impl_.udp_socket.async_send_to(net::buffer(*held), *udp_endpoint_,
                                     [self = shared_from_this(), held](const boost::system::error_code&, std::size_t) {
                                       --self->udp_in_flight_;
                                     });
    }
    ++frames_sent_;
    return;
  }
  // The per-subscriber head (length prefix, ServerMessage tag, ids); the body is shared.
  std::string head = wire::frame_head_for(view_id, sub, stream_id, body->size(), true);
  auto [pos, inserted] = pending_frames_.try_emplace(sub);
  if (!inserted) {
    ++frames_dropped_;
    ++it->second.dropped;
  }
  pos->second = PendingFrame{std::move(head), body};
  note_queue();
  flush();
}

void Session::flush() {
  if (writing_ || stopped_) return;
  if (replies_.empty() && pending_frames_.empty()) {
    if (close_after_flush_) stop("closed by the server");
    return;
  }
  std::vector<net::const_buffer> buffers;
  hold_.clear();
  hold_heads_.clear();
  in_flight_bytes_ = 0;
  in_flight_reply_bytes_ = 0;
  for (auto& r : replies_) {
    buffers.push_back(net::buffer(*r));
    in_flight_reply_bytes_ += r->size();
    hold_.push_back(std::move(r));
  }
  replies_.clear();
  reply_bytes_ = 0;
  in_flight_bytes_ = in_flight_reply_bytes_;
  hold_heads_.reserve(pending_frames_.size());
  for (auto& [sub, f] : pending_frames_) {
    hold_heads_.push_back(std::move(f.head));
    in_flight_bytes_ += hold_heads_.back().size() + f.body->size();
    hold_.push_back(std::move(f.body));
    ++frames_sent_;
  }
  // Buffers point into hold_heads_ (reserved, so stable) and the held bodies.
  std::size_t head_index = 0;
  for (std::size_t i = buffers.size(); i < hold_.size(); ++i, ++head_index) {
    buffers.push_back(net::buffer(hold_heads_[head_index]));
    buffers.push_back(net::buffer(*hold_[i]));
  }
  pending_frames_.clear();
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
    if (self->reply_bytes_ <= self->impl_.cfg.max_reply_queue_bytes) self->read_gate_.cancel();
    self->flush();
  });
}

void Session::arm_watchdog() {
  using std::chrono::milliseconds;
  const auto& c = impl_.cfg;
  const auto period = std::max(milliseconds(10), std::min({c.heartbeat_interval, c.idle_timeout, c.write_timeout}) / 4);
  watchdog_.expires_after(period);
  watchdog_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
    if (ec || self->stopped_) return;
    const auto now = Clock::now();
    const auto& cfg = self->impl_.cfg;
    if (now - self->last_read_ > cfg.idle_timeout) {
      spdlog::warn("conn {}: idle for more than {} ms", self->id_, cfg.idle_timeout.count());
      self->stop("idle timeout");
      return;
    }
    if (self->writing_ && now - self->write_started_ > cfg.write_timeout) {
      spdlog::warn("conn {}: a write made no progress for {} ms: the client is not reading", self->id_,
                   cfg.write_timeout.count());
      self->stop("write timeout");
      return;
    }
    if (!self->writing_ && now - self->last_write_ > cfg.heartbeat_interval) {
      pb::ServerMessage hb;
      hb.mutable_heartbeat()->set_client_time_ns(0);
      self->send(hb);
      self->last_write_ = now;
    }
    self->arm_watchdog();
  });
}

net::awaitable<void> Session::read_loop(std::shared_ptr<Session> self) {
  std::array<std::uint8_t, wire::kLengthPrefixBytes> prefix{};
  std::string body;
  for (;;) {
    boost::system::error_code ec;
    // Back-pressure: a client that sends requests faster than it reads the
    // replies waits here; its replies never pile up beyond the cap.
    while (!stopped_ && reply_bytes_ > impl_.cfg.max_reply_queue_bytes) {
      read_gate_.expires_at(Clock::time_point::max());
      co_await read_gate_.async_wait(net::redirect_error(net::use_awaitable, ec));
    }
    if (stopped_) co_return;
    co_await net::async_read(socket_, net::buffer(prefix), net::redirect_error(net::use_awaitable, ec));
    if (stopped_) co_return;
    if (ec) {
      if (ec == net::error::eof) {
        stop("the client closed the connection");
      } else {
        stop("read failed: " + ec.message());
      }
      co_return;
    }
    last_read_ = Clock::now();
    const std::uint32_t length = wire::read_length_prefix(prefix);
    if (auto s = wire::check_length(length, impl_.cfg.max_message_bytes); !s.ok()) {
      spdlog::warn("conn {}: bad length prefix: {}; closing", id_, s.error().message);
      stop("bad length prefix");
      co_return;
    }
    body.resize(length);
    co_await net::async_read(socket_, net::buffer(body), net::redirect_error(net::use_awaitable, ec));
    if (stopped_) co_return;
    if (ec) {
      spdlog::warn("conn {}: truncated message: {} of {} bytes announced; closing", id_, 0, length);
      stop(ec == net::error::eof ? "truncated message" : "read failed: " + ec.message());
      co_return;
    }
    last_read_ = Clock::now();
    handle(body);
  }
}

void Session::handle(const std::string& bytes) {
  pb::ClientMessage req;
  if (!req.ParseFromString(bytes)) {
    spdlog::warn("conn {}: a {}-byte message is not a ClientMessage", id_, bytes.size());
    send(error_message(0, pb::ERROR_CODE_BAD_REQUEST, "cannot parse the message as a gmr.stream.v1.ClientMessage"));
    return;
  }
  if (req.body_case() == pb::ClientMessage::kHeartbeat) return;  // last_read_ already counts it
  pb::ServerMessage reply;
  try {
    reply = dispatch(req);
  } catch (const RequestError& e) {
    spdlog::debug("conn {}: request {} refused: {}", id_, req.request_id(), e.message);
    reply = error_message(req.request_id(), e.code, e.message);
  }
  reply.set_request_id(req.request_id());
  send(reply);
}

View& Session::view(std::uint32_t id) {
  auto it = views_.find(id);
  if (it == views_.end()) throw RequestError{pb::ERROR_CODE_NOT_FOUND, "unknown view " + std::to_string(id)};
  return *it->second;
}

Session::Subscription& Session::subscription(std::uint32_t id) {
  auto it = subs_.find(id);
  if (it == subs_.end()) throw RequestError{pb::ERROR_CODE_NOT_FOUND, "unknown subscription " + std::to_string(id)};
  return it->second;
}

pb::ViewInfo Session::view_info(const View& v) const {
  pb::ViewInfo info;
  info.set_view_id(v.id());
  info.set_motion(v.motion_name());
  info.set_skeleton_version(v.content()->skeleton_version);
  wire::to_proto(v.motion().skeleton, *info.mutable_skeleton());
  if (v.content()->relative_to >= 0) info.set_relative_to(v.motion().skeleton.joint(v.content()->relative_to).name);
  info.set_frame_count(v.motion().frame_count);
  info.set_frame_time(v.motion().frame_time);
  return info;
}

Result<std::vector<int>> Session::resolve_joints(const View& v, const std::vector<std::string>& names) const {
  std::vector<int> out;
  if (names.empty()) {
    for (int j = 0; j < static_cast<int>(v.motion().skeleton.size()); ++j) out.push_back(j);
    return out;
  }
  for (const auto& n : names) {
    auto j = v.joint_index(n);
    if (!j.ok()) return j.error();
    out.push_back(*j);
  }
  return out;
}

// Gives `sub` a stream of its own (same content and position) when it shares one.
std::shared_ptr<Stream> Session::detach(Subscription& sub) {
  auto& old = sub.stream;
  if (old->targets().size() <= 1) {
    if (!old->key.empty()) {
      impl_.shared_streams.erase(old->key);
      old->key.clear();
    }
    return old;
  }
  impl_.prune_streams();
  auto fresh = old->clone(impl_.next_stream_id++);
  impl_.streams[fresh->id()] = fresh;
  auto it = std::find_if(old->targets().begin(), old->targets().end(), [&](const Stream::Target& t) {
    return t.subscription_id == sub.id && t.session.lock().get() == this;
  });
  if (it != old->targets().end()) {
    fresh->targets().push_back(*it);
    old->targets().erase(it);
  }
  sub.stream = fresh;
  return fresh;
}

void Session::drop_subscription(std::uint32_t id) {
  auto it = subs_.find(id);
  if (it == subs_.end()) return;
  auto& targets = it->second.stream->targets();
  std::erase_if(targets, [&](const Stream::Target& t) { return t.subscription_id == id && t.session.lock().get() == this; });
  if (targets.empty()) it->second.stream->stop();
  pending_frames_.erase(id);
  subs_.erase(it);
}

void Session::view_changed(View& v) {
  std::vector<std::pair<std::uint32_t, std::string>> ended;
  for (auto& [id, sub] : subs_) {
    if (sub.view_id != v.id()) continue;
    auto joints = resolve_joints(v, sub.joint_names);
    if (!joints.ok()) {
      ended.emplace_back(id, "the view changed: " + joints.error().message);
      continue;
    }
    detach(sub)->set_content(v.content(), std::move(joints).value());
  }
  for (auto& [id, reason] : ended) {
    pb::ServerMessage m;
    m.mutable_subscription_ended()->set_subscription_id(id);
    m.mutable_subscription_ended()->set_reason(reason);
    drop_subscription(id);
    send(m);
  }
}

void Session::subscription_ended(std::uint32_t sub, std::uint64_t sent, const std::string& reason) {
  auto it = subs_.find(sub);
  if (it == subs_.end()) return;
  pb::ServerMessage m;
  m.mutable_subscription_ended()->set_subscription_id(sub);
  m.mutable_subscription_ended()->set_frames_sent(sent);
  m.mutable_subscription_ended()->set_frames_dropped(it->second.dropped);
  m.mutable_subscription_ended()->set_reason(reason);
  // The frame still pending goes out before the end notice.
  if (auto f = pending_frames_.find(sub); f != pending_frames_.end()) {
    auto bytes = std::make_shared<const std::string>(f->second.head + *f->second.body);
    reply_bytes_ += bytes->size();
    replies_.push_back(std::move(bytes));
    pending_frames_.erase(f);
  }
  auto& targets = it->second.stream->targets();
  std::erase_if(targets, [&](const Stream::Target& t) { return t.subscription_id == sub && t.session.lock().get() == this; });
  subs_.erase(it);
  send(m);
}

void Session::udp_registered(const udp::endpoint& ep) {
  const bool first = !udp_endpoint_ || *udp_endpoint_ != ep;
  udp_endpoint_ = ep;
  if (first) spdlog::info("conn {}: UDP endpoint {}:{} registered", id_, ep.address().to_string(), ep.port());
  pb::ServerMessage m;
  m.mutable_udp_registered()->set_endpoint(ep.address().to_string() + ":" + std::to_string(ep.port()));
  send(m);
}

// ---------------------------------------------------------------------------
// Requests

namespace {

void require(bool ok, pb::ErrorCode code, const std::string& message) {
  if (!ok) throw RequestError{code, message};
}

void check_op(const Status& s) {
  if (!s.ok()) throw RequestError{pb::ERROR_CODE_FAILED_PRECONDITION, s.error().to_string()};
}

std::vector<std::string> names_of(const google::protobuf::RepeatedPtrField<std::string>& names) {
  return {names.begin(), names.end()};
}

// Ops fail with NOT_FOUND for an unknown joint, FAILED_PRECONDITION otherwise.
template <class F>
void run_op(View& v, const std::vector<std::string>& joints, F&& op) {
  for (const auto& j : joints) {
    auto idx = v.joint_index(j);
    if (!idx.ok()) throw RequestError{pb::ERROR_CODE_NOT_FOUND, idx.error().message};
  }
  check_op(op());
}

}  // namespace

pb::ServerMessage Session::dispatch(const pb::ClientMessage& req) {
  pb::ServerMessage out;
  using C = pb::ClientMessage;
  if (req.body_case() == C::kHello) {
    const auto& h = req.hello();
    if (h.protocol_version() != wire::kProtocolVersion) {
      spdlog::warn("conn {}: refused protocol version {} (this server speaks {})", id_, h.protocol_version(),
                   wire::kProtocolVersion);
      close_after_flush_ = true;
      throw RequestError{pb::ERROR_CODE_VERSION_MISMATCH,
                         "client speaks protocol version " + std::to_string(h.protocol_version()) +
                             ", this server speaks version " + std::to_string(wire::kProtocolVersion)};
    }
    handshaked_ = true;
    spdlog::info("conn {}: hello from '{}'", id_, h.client_name());
    auto* r = out.mutable_hello();
    r->set_protocol_version(wire::kProtocolVersion);
    r->set_server_name(impl_.cfg.server_name);
    r->set_session_token(token_);
    r->set_udp_port(impl_.udp_port);
    r->set_max_message_bytes(impl_.cfg.max_message_bytes);
    r->set_heartbeat_interval_ms(static_cast<std::uint32_t>(impl_.cfg.heartbeat_interval.count()));
    r->set_idle_timeout_ms(static_cast<std::uint32_t>(impl_.cfg.idle_timeout.count()));
    return out;
  }
  require(req.body_case() != C::BODY_NOT_SET, pb::ERROR_CODE_UNKNOWN_REQUEST,
          "unknown or empty request (this server speaks protocol version " + std::to_string(wire::kProtocolVersion) +
              ")");
  require(handshaked_, pb::ERROR_CODE_HANDSHAKE_REQUIRED, "send Hello first");

  switch (req.body_case()) {
    case C::kListMotions: {
      auto* list = out.mutable_motions();
      for (const auto& e : impl_.library) {
        auto* m = list->add_motions();
        m->set_name(e.name);
        m->set_joint_count(static_cast<std::uint32_t>(e.motion->skeleton.size()));
        m->set_frame_count(e.motion->frame_count);
        m->set_frame_time(e.motion->frame_time);
        m->set_source(e.source);
      }
      return out;
    }
    case C::kGetSkeleton: {
      auto it = impl_.by_name.find(req.get_skeleton().motion());
      require(it != impl_.by_name.end(), pb::ERROR_CODE_NOT_FOUND, "unknown motion '" + req.get_skeleton().motion() + "'");
      out.mutable_skeleton()->set_motion(it->first);
      wire::to_proto(impl_.library[it->second].motion->skeleton, *out.mutable_skeleton()->mutable_skeleton());
      return out;
    }
    case C::kCreateView: {
      auto it = impl_.by_name.find(req.create_view().motion());
      require(it != impl_.by_name.end(), pb::ERROR_CODE_NOT_FOUND, "unknown motion '" + req.create_view().motion() + "'");
      require(views_.size() < impl_.cfg.max_views_per_connection, pb::ERROR_CODE_RESOURCE_EXHAUSTED,
              "at most " + std::to_string(impl_.cfg.max_views_per_connection) + " views per connection");
      const std::uint32_t id = next_view_++;
      auto v = std::make_unique<View>(id, it->first, impl_.library[it->second].motion);
      *out.mutable_view() = view_info(*v);
      views_.emplace(id, std::move(v));
      return out;
    }
    case C::kCloseView: {
      View& v = view(req.close_view().view_id());
      std::vector<std::uint32_t> ids;
      for (auto& [id, sub] : subs_) {
        if (sub.view_id == v.id()) ids.push_back(id);
      }
      for (auto id : ids) drop_subscription(id);
      views_.erase(v.id());
      out.mutable_ack();
      return out;
    }
    case C::kShiftRoot: {
      View& v = view(req.shift_root().view_id());
      run_op(v, {req.shift_root().joint()}, [&] { return v.shift_root(req.shift_root().joint()); });
      view_changed(v);
      *out.mutable_view() = view_info(v);
      return out;
    }
    case C::kSplit: {
      View& v = view(req.split().view_id());
      run_op(v, {req.split().joint()}, [&] { return v.split(req.split().joint()); });
      view_changed(v);
      *out.mutable_view() = view_info(v);
      return out;
    }
    case C::kJoin: {
      View& v = view(req.join().view_id());
      double spread = 0.0;
      run_op(v, {req.join().root()}, [&] { return v.join(req.join().root(), &spread); });
      view_changed(v);
      *out.mutable_view() = view_info(v);
      out.mutable_view()->set_join_offset_spread(spread);
      return out;
    }
    case C::kSetRoots: {
      View& v = view(req.set_roots().view_id());
      const auto roots = names_of(req.set_roots().roots());
      require(!roots.empty(), pb::ERROR_CODE_BAD_REQUEST, "set roots: give at least one root");
      run_op(v, roots, [&] { return v.set_roots(roots); });
      view_changed(v);
      *out.mutable_view() = view_info(v);
      return out;
    }
    case C::kStripDummies: {
      View& v = view(req.strip_dummies().view_id());
      std::vector<std::string> removed;
      run_op(v, {}, [&] { return v.strip_dummies(&removed); });
      view_changed(v);
      *out.mutable_view() = view_info(v);
      for (auto& r : removed) out.mutable_view()->add_removed(r);
      return out;
    }
    case C::kSetCoordinates: {
      View& v = view(req.set_coordinates().view_id());
      const std::string& j = req.set_coordinates().relative_to();
      run_op(v, j.empty() ? std::vector<std::string>{} : std::vector<std::string>{j}, [&] { return v.set_relative_to(j); });
      view_changed(v);
      *out.mutable_view() = view_info(v);
      return out;
    }
    case C::kQueryFrames:
      return query(req.query_frames());
    case C::kSubscribe:
      return subscribe(req.subscribe());
    case C::kUnsubscribe: {
      subscription(req.unsubscribe().subscription_id());
      drop_subscription(req.unsubscribe().subscription_id());
      out.mutable_ack();
      return out;
    }
    case C::kPause: {
      detach(subscription(req.pause().subscription_id()))->pause();
      out.mutable_ack();
      return out;
    }
    case C::kResume: {
      subscription(req.resume().subscription_id()).stream->resume();
      out.mutable_ack();
      return out;
    }
    case C::kSeek: {
      auto& sub = subscription(req.seek().subscription_id());
      const auto& sched = sub.stream->schedule();
      require(req.seek().frame() >= sched.start && req.seek().frame() < sched.end, pb::ERROR_CODE_BAD_REQUEST,
              "seek to frame " + std::to_string(req.seek().frame()) + ": the subscription plays frames [" +
                  std::to_string(sched.start) + ", " + std::to_string(sched.end) + ")");
      detach(sub)->seek(req.seek().frame());
      out.mutable_ack();
      return out;
    }
    case C::kGetStats: {
      auto* st = out.mutable_stats();
      st->set_connections(static_cast<std::uint32_t>(impl_.sessions.size()));
      impl_.prune_streams();
      st->set_streams(static_cast<std::uint32_t>(impl_.streams.size()));
      st->set_frames_computed(impl_.frames_computed);
      st->set_frames_encoded(impl_.frames_encoded);
      st->set_frames_sent(frames_sent_);
      st->set_frames_dropped(frames_dropped_);
      st->set_queued_bytes(queued_bytes());
      st->set_max_queued_bytes(max_queued_bytes_);
      return out;
    }
    default:
      throw RequestError{pb::ERROR_CODE_UNKNOWN_REQUEST, "unknown request"};
  }
}

pb::ServerMessage Session::query(const pb::QueryFrames& r) {
  View& v = view(r.view_id());
  const Motion& m = v.motion();
  const std::uint64_t begin = r.begin();
  const std::uint64_t end = r.end() == 0 ? begin + 1 : r.end();
  require(begin < end && end <= m.frame_count, pb::ERROR_CODE_BAD_REQUEST,
          "frames [" + std::to_string(begin) + ", " + std::to_string(end) + ") are not within the motion's " +
              std::to_string(m.frame_count) + " frames");
  auto joints = resolve_joints(v, names_of(r.joints()));
  if (!joints.ok()) throw RequestError{pb::ERROR_CODE_NOT_FOUND, joints.error().message};
  // Refuse before computing anything a reply too big to send.
  const std::uint64_t per_frame = joints->size() * (3 + (r.orientations() ? 4 : 0)) * 9 + 8;
  const std::uint64_t estimate = (end - begin) * per_frame + 64;
  require(estimate <= impl_.cfg.max_message_bytes, pb::ERROR_CODE_RESOURCE_EXHAUSTED,
          "a query of " + std::to_string(end - begin) + " frames would take about " + std::to_string(estimate) +
              " bytes, above the limit of " + std::to_string(impl_.cfg.max_message_bytes) + ": ask for fewer frames");
  pb::ServerMessage out;
  auto* b = out.mutable_frames();
  b->set_view_id(v.id());
  b->set_skeleton_version(v.content()->skeleton_version);
  b->set_begin(static_cast<std::uint32_t>(begin));
  b->set_end(static_cast<std::uint32_t>(end));
  for (int j : *joints) b->add_joints(static_cast<std::uint32_t>(j));
  const std::size_t n = m.skeleton.size();
  std::vector<Eigen::Vector3d> pos(n);
  std::vector<Eigen::Matrix3d> rot(r.orientations() ? n : 0);
  b->mutable_positions()->Reserve(static_cast<int>((end - begin) * joints->size() * 3));
  for (std::uint64_t f = begin; f < end; ++f) {
    compute_view_frame(*v.content(), f, pos, rot);
    for (int j : *joints) {
      const auto& p = pos[static_cast<std::size_t>(j)];
      b->add_positions(p.x());
      b->add_positions(p.y());
      b->add_positions(p.z());
      if (r.orientations()) {
        const Eigen::Quaterniond q(rot[static_cast<std::size_t>(j)]);
        b->add_orientations(q.x());
        b->add_orientations(q.y());
        b->add_orientations(q.z());
        b->add_orientations(q.w());
      }
    }
  }
  return out;
}

pb::ServerMessage Session::subscribe(const pb::Subscribe& r) {
  View& v = view(r.view_id());
  const Motion& m = v.motion();
  require(subs_.size() < impl_.cfg.max_subscriptions_per_connection, pb::ERROR_CODE_RESOURCE_EXHAUSTED,
          "at most " + std::to_string(impl_.cfg.max_subscriptions_per_connection) + " subscriptions per connection");
  Stream::Schedule s;
  s.start = r.start_frame();
  s.end = r.end_frame() == 0 ? static_cast<std::uint32_t>(m.frame_count) : r.end_frame();
  require(s.start < s.end && s.end <= m.frame_count, pb::ERROR_CODE_BAD_REQUEST,
          "frames [" + std::to_string(s.start) + ", " + std::to_string(s.end) + ") are not within the motion's " +
              std::to_string(m.frame_count) + " frames");
  s.loop = r.loop();
  s.speed = r.speed() == 0.0 ? 1.0 : r.speed();
  require(std::isfinite(s.speed) && s.speed >= kMinSpeed && s.speed <= kMaxSpeed, pb::ERROR_CODE_BAD_REQUEST,
          "speed " + std::to_string(r.speed()) + " is not within [" + std::to_string(kMinSpeed) + ", " +
              std::to_string(kMaxSpeed) + "]");
  s.rate = r.rate_hz() == 0.0 ? s.speed / m.frame_time : r.rate_hz();
  require(std::isfinite(s.rate) && s.rate >= kMinRateHz && s.rate <= kMaxRateHz, pb::ERROR_CODE_BAD_REQUEST,
          "output rate " + std::to_string(s.rate) + " Hz" +
              (r.rate_hz() == 0.0 ? std::string(" (the motion's rate times speed)") : std::string()) +
              " is not within [" + std::to_string(kMinRateHz) + ", " + std::to_string(kMaxRateHz) + "] Hz");
  s.skip_repeats = r.skip_repeats();
  const bool use_udp = r.transport() == pb::TRANSPORT_UDP;
  require(!use_udp || udp_endpoint_.has_value(), pb::ERROR_CODE_FAILED_PRECONDITION,
          "UDP transport: register this connection's UDP endpoint first (send the session token to UDP port " +
              std::to_string(impl_.udp_port) + ")");
  const auto names = names_of(r.joints());
  auto joints = resolve_joints(v, names);
  if (!joints.ok()) throw RequestError{pb::ERROR_CODE_NOT_FOUND, joints.error().message};
  const bool f64 = r.precision() == pb::PRECISION_FLOAT64;

  // Streams with the same content and schedule can share one FK and one
  // encoding per tick. The key names everything that shapes the bytes.
  std::string key;
  if (r.shared()) {
    std::string structure;
    for (const auto& j : m.skeleton.joints()) structure += j.name + "<" + std::to_string(j.parent) + "," + std::to_string(j.soft_parent) + ";";
    key = v.motion_name() + "|" + std::to_string(std::hash<std::string>{}(structure)) + "|" +
          std::to_string(v.content()->relative_to) + "|" + std::to_string(r.orientations()) + std::to_string(f64) +
          "|" + std::to_string(s.start) + ":" + std::to_string(s.end) + "|" + std::to_string(s.loop) + "|" +
          std::to_string(s.speed) + "|" + std::to_string(s.rate) + "|" + std::to_string(s.skip_repeats) + "|";
    for (int j : *joints) key += std::to_string(j) + ",";
  }
  std::shared_ptr<Stream> stream;
  bool joined = false;
  if (!key.empty()) {
    if (auto it = impl_.shared_streams.find(key); it != impl_.shared_streams.end()) {
      stream = it->second.lock();
      joined = stream && !stream->paused() && !stream->targets().empty();
      if (!joined) stream.reset();
    }
  }
  if (!stream) {
    impl_.prune_streams();
    stream = std::make_shared<Stream>(impl_, impl_.next_stream_id++, v.content(), *joints, r.orientations(), f64, s);
    impl_.streams[stream->id()] = stream;
    if (!key.empty()) {
      stream->key = key;
      impl_.shared_streams[key] = stream;
    }
  }
  const std::uint32_t id = next_sub_++;
  stream->targets().push_back({weak_from_this(), id, v.id(), use_udp, 0, r.max_frames()});
  subs_[id] = Subscription{id, v.id(), stream, use_udp, names, 0};
  if (!joined) stream->start();

  pb::ServerMessage out;
  auto* sub = out.mutable_subscribed();
  sub->set_subscription_id(id);
  sub->set_view_id(v.id());
  sub->set_skeleton_version(v.content()->skeleton_version);
  for (int j : *joints) sub->add_joints(static_cast<std::uint32_t>(j));
  sub->set_rate_hz(s.rate);
  sub->set_stream_id(stream->id());
  sub->set_joined_running(joined);
  spdlog::debug("conn {}: subscription {} on view {} (stream {}, {}, {} Hz)", id_, id, v.id(), stream->id(),
                use_udp ? "UDP" : "TCP", s.rate);
  return out;
}

// ---------------------------------------------------------------------------
// Listener and UDP registration

void Server::Impl::accept_loop() {
  acceptor.async_accept([this](const boost::system::error_code& ec, tcp::socket socket) {
    if (ec) {
      if (ec == net::error::operation_aborted || stopping) return;
      spdlog::warn("accept failed: {}", ec.message());
    } else if (stopping) {
      return;
    } else if (sessions.size() >= cfg.max_connections) {
      ++connections_refused;
      spdlog::warn("refusing a connection: {} connections open (--max-connections)", sessions.size());
      auto bytes = std::make_shared<std::string>(
          wire::frame_message(error_message(0, pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                                            "the server has reached its limit of " +
                                                std::to_string(cfg.max_connections) + " connections"))
              .value());
      auto sock = std::make_shared<tcp::socket>(std::move(socket));
      net::async_write(*sock, net::buffer(*bytes), [sock, bytes](const boost::system::error_code&, std::size_t) {
        boost::system::error_code ignored;
        sock->shutdown(tcp::socket::shutdown_both, ignored);
        sock->close(ignored);
      });
    } else {
      const std::uint64_t id = next_session_id++;
      auto s = std::make_shared<Session>(*this, std::move(socket), id);
      sessions[id] = s;
      s->start();
    }
    accept_loop();
  });
}

void Server::Impl::udp_loop() {
  udp_socket.async_receive_from(net::buffer(udp_buffer), udp_sender, [this](const boost::system::error_code& ec,
                                                                            std::size_t n) {
    if (ec == net::error::operation_aborted || stopping) return;
    if (!ec) {
      const auto token = wire::parse_register_datagram(std::string_view(udp_buffer.data(), n));
      std::shared_ptr<Session> s;
      if (token) {
        if (auto it = tokens.find(*token); it != tokens.end()) s = it->second.lock();
      }
      if (s && !s->stopped()) {
        s->udp_registered(udp_sender);
      } else {
        // Never answer: an unregistered address gets nothing from this server.
        if (udp_rejected++ % 1000 == 0) {
          spdlog::warn("ignoring a {}-byte UDP datagram from {}:{}: {} ({} so far)", n,
                       udp_sender.address().to_string(), udp_sender.port(),
                       token ? "unknown session token" : "not a registration datagram", udp_rejected);
        }
      }
    }
    udp_loop();
  });
}

void Server::Impl::begin_stop() {
  if (stopping) return;
  stopping = true;
  prune_streams();
  spdlog::info("stopping: {} connections, {} streams", sessions.size(), streams.size());
  boost::system::error_code ec;
  acceptor.close(ec);
  udp_socket.close(ec);
  for (auto& [id, weak] : streams) {
    if (auto s = weak.lock()) s->stop();
  }
  auto open = sessions;
  for (auto& [id, weak] : open) {
    if (auto s = weak.lock()) s->finish();
  }
  // Whatever has not drained by the deadline is closed; the io_context then runs out of work.
  if (sessions.empty()) return;
  grace_timer = std::make_unique<net::steady_timer>(io, cfg.shutdown_grace);
  grace_timer->async_wait([this](const boost::system::error_code&) {
    auto left = sessions;
    for (auto& [id, weak] : left) {
      if (auto s = weak.lock()) s->stop("server shutdown");
    }
  });
}

ServerStats Server::Impl::snapshot() const {
  ServerStats st;
  st.connections = sessions.size();
  for (auto& [id, w] : streams) {
    if (auto s = w.lock(); s && !s->targets().empty()) ++st.streams;
  }
  st.frames_computed = frames_computed;
  st.frames_encoded = frames_encoded;
  st.udp_rejected = udp_rejected;
  st.connections_refused = connections_refused;
  for (auto& [id, w] : sessions) {
    if (auto s = w.lock()) st.sessions.push_back(s->stats());
  }
  return st;
}

// ---------------------------------------------------------------------------

Server::Server(ServerConfig config, std::vector<LibraryEntry> library) : impl_(std::make_shared<Impl>()) {
  impl_->cfg = std::move(config);
  impl_->library = std::move(library);
  for (std::size_t i = 0; i < impl_->library.size(); ++i) impl_->by_name.emplace(impl_->library[i].name, i);
}

Server::~Server() { stop(); }

void Server::start() {
  auto& d = *impl_;
  if (d.started) throw std::runtime_error("server already started");
  boost::system::error_code ec;
  const auto address = net::ip::make_address(d.cfg.bind_address, ec);
  if (ec) throw std::runtime_error("bad bind address '" + d.cfg.bind_address + "': " + ec.message());
  const tcp::endpoint tcp_ep(address, d.cfg.port);
  d.acceptor.open(tcp_ep.protocol());
  d.acceptor.set_option(tcp::acceptor::reuse_address(true));
  d.acceptor.bind(tcp_ep, ec);
  if (ec) throw std::runtime_error("cannot bind TCP " + d.cfg.bind_address + ":" + std::to_string(d.cfg.port) + ": " + ec.message());
  d.acceptor.listen(net::socket_base::max_listen_connections);
  d.tcp_port = d.acceptor.local_endpoint().port();
  const std::uint16_t udp_port = d.cfg.udp_port < 0 ? d.tcp_port : static_cast<std::uint16_t>(d.cfg.udp_port);
  const udp::endpoint udp_ep(address, udp_port);
  d.udp_socket.open(udp_ep.protocol());
  d.udp_socket.bind(udp_ep, ec);
  if (ec) throw std::runtime_error("cannot bind UDP " + d.cfg.bind_address + ":" + std::to_string(udp_port) + ": " + ec.message());
  d.udp_port = d.udp_socket.local_endpoint().port();
  d.started = true;
  d.accept_loop();
  d.udp_loop();
  spdlog::info("serving {} motions on tcp {}:{} and udp {}:{}", d.library.size(), d.cfg.bind_address, d.tcp_port,
               d.cfg.bind_address, d.udp_port);
  d.thread = std::thread([impl = impl_] {
    try {
      impl->io.run();
    } catch (const std::exception& e) {
      spdlog::critical("I/O thread stopped: {}", e.what());
    }
    impl->stopped.set_value();
  });
}

std::uint16_t Server::tcp_port() const { return impl_->tcp_port; }
std::uint16_t Server::udp_port() const { return impl_->udp_port; }

void Server::stop() {
  auto& d = *impl_;
  if (!d.started) return;
  net::post(d.io, [impl = impl_] { impl->begin_stop(); });
  wait();
}

void Server::wait() {
  auto& d = *impl_;
  if (!d.started) return;
  d.stopped_future.wait();
  if (d.thread.joinable()) d.thread.join();
}

ServerStats Server::stats() const {
  auto& d = *impl_;
  if (!d.started || d.stopped_future.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    return d.snapshot();
  }
  std::promise<ServerStats> p;
  auto f = p.get_future();
  net::post(d.io, [&] { p.set_value(d.snapshot()); });
  // The I/O thread may be finishing a stop and never run the snapshot.
  if (f.wait_for(std::chrono::seconds(5)) != std::future_status::ready) return {};
  return f.get();
}

}  // namespace gmr::server
