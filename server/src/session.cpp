#include "session.h"

#include <cmath>

#include "gmr/wire/convert.h"
#include "gmr/wire/frame_encoding.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"

namespace gmr::server {

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
  // Bounded: beyond the cap the oldest waiting frame gives way (latest wins).
  auto& queue = pending_frames_[sub];
  if (queue.size() >= std::max<std::size_t>(1, impl_.cfg.frames_per_subscription)) {
    queue.pop_front();
    ++frames_dropped_;
    ++it->second.dropped;
  }
  queue.push_back(PendingFrame{std::move(head), body});
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
  std::size_t frames = 0;
  for (const auto& [sub, queue] : pending_frames_) frames += queue.size();
  hold_heads_.reserve(frames);
  for (auto& [sub, queue] : pending_frames_) {
    for (auto& f : queue) {
      hold_heads_.push_back(std::move(f.head));
      in_flight_bytes_ += hold_heads_.back().size() + f.body->size();
      hold_.push_back(std::move(f.body));
      ++frames_sent_;
    }
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
    for (const auto& frame : f->second) {
      auto bytes = std::make_shared<const std::string>(frame.head + *frame.body);
      reply_bytes_ += bytes->size();
      replies_.push_back(std::move(bytes));
      ++frames_sent_;
    }
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
      auto v = std::make_unique<View>(id, it->first, impl_.library[it->second].motion, impl_.compiled_form(it->second));
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
      st->set_frames_computed_float(impl_.frames_computed_float);
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

}  // namespace gmr::server
