#include "client_impl.h"

namespace gmr::client {

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

namespace {

ServerHello hello_of(const pb::HelloReply& h) {
  ServerHello s;
  s.protocol_version = h.protocol_version();
  s.server_name = h.server_name();
  if (h.udp_token().size() == s.udp_token.size())
    std::memcpy(s.udp_token.data(), h.udp_token().data(), s.udp_token.size());
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

}  // namespace

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
  net::async_connect(d.socket.tcp(), endpoints, [&connected](const boost::system::error_code& e, const tcp::endpoint&) {
    connected.set_value(e);
  });
  if (d.own_loop) {
    d.guard.emplace(d.io.get_executor());
    std::promise<void> done;
    d.thread_done = done.get_future();
    d.thread = std::thread([impl = c->impl_, done = std::move(done)]() mutable {
      impl->io.run();
      done.set_value();
    });
  }
  const std::string where = options.host + ":" + std::to_string(options.port);
  if (connected_future.wait_for(options.timeout) != std::future_status::ready) {
    net::post(d.strand, [impl = c->impl_] {
      boost::system::error_code e;
      impl->socket.tcp().close(e);
    });
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
  net::post(d.strand, [impl = c->impl_] { impl->read_more(); });

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
  // The UDP socket is opened on the strand, as every socket of this client
  // is used: the server may have gone already (closed, reset, garbage right
  // after its HelloReply), and the I/O thread shut everything meanwhile.
  std::promise<void> udp_ready;
  auto udp_future = udp_ready.get_future();
  net::post(d.strand, [impl = c->impl_, address = remote.address(), &udp_ready] {
    if (impl->open) {
      boost::system::error_code e;
      impl->udp_socket.open(address.is_v4() ? udp::v4() : udp::v6(), e);
      if (!e) impl->udp_socket.bind(udp::endpoint(address.is_loopback() ? address : net::ip::address(), 0), e);
      // A deep receive buffer rides out scheduling stalls of the I/O thread
      // (the kernel caps it at net.core.rmem_max).
      if (!e) impl->udp_socket.set_option(net::socket_base::receive_buffer_size(4 << 20), e);
      impl->udp_open = !e;
      if (impl->udp_open) impl->read_udp();
      impl->arm_heartbeat();
    } else {
      impl->shut();
    }
    udp_ready.set_value();
  });
  udp_future.wait();
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
      impl->shut();
      done->set_value();
    });
    if (!impl_->loop->runs_here()) finished.wait();
    return;
  }
  if (!impl_->thread.joinable()) return;
  net::post(impl_->strand, [impl = impl_] {
    impl->fail("closed by the client");
    impl->shut();
    impl->guard.reset();
  });
  if (impl_->thread.get_id() == std::this_thread::get_id()) {
    impl_->thread.detach();  // close() from a callback: the thread ends by itself
    return;
  }
  // Every socket is closed and every timer cancelled: the loop runs out of
  // work at once. Should a handler still wait (a bug, or a callback that
  // blocks), the loop is stopped after kCloseGrace rather than close()
  // waiting for ever; what it left queued is then never run.
  if (impl_->thread_done.wait_for(Impl::kCloseGrace) != std::future_status::ready) impl_->io.stop();
  impl_->thread.join();
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
    out.push_back(MotionInfo{i.name(), i.joint_count(), i.frame_count(), i.frame_time(), i.source(),
                             i.metres_per_unit(), i.version()});
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

Result<ViewState> Client::retarget(std::uint32_t view, const Skeleton& rig, const std::vector<double>& reference,
                                   const std::map<std::string, std::string>& rig_map,
                                   const std::map<std::string, std::string>& source_map, double rig_metres_per_unit) {
  pb::ClientMessage m;
  auto* r = m.mutable_retarget();
  r->set_view_id(view);
  wire::to_proto(rig, *r->mutable_target());
  r->mutable_target()->set_metres_per_unit(rig_metres_per_unit);
  r->mutable_reference()->Add(reference.begin(), reference.end());
  for (const auto& [role, joint] : rig_map) (*r->mutable_target_map())[role] = joint;
  for (const auto& [role, joint] : source_map) (*r->mutable_source_map())[role] = joint;
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
  // The frames asked for (end 0: the one frame at begin), nothing else.
  if (b->begin != begin || b->end != (end == 0 ? std::uint64_t{begin} + 1 : end)) {
    return make_error(ErrorKind::kInvalidData, "the server answered frames [" + std::to_string(b->begin) + ", " +
                                                   std::to_string(b->end) + ") to a query of [" +
                                                   std::to_string(begin) + ", " + std::to_string(end) + ")");
  }
  QueryResult out;
  out.skeleton_version = b->skeleton_version;
  out.metres_per_unit = r->frames().metres_per_unit();
  out.begin = b->begin;
  out.end = b->end;
  out.joints = std::move(b->joints);
  out.positions = std::move(b->positions);
  out.orientations = std::move(b->orientations);
  out.local_rotations = std::move(b->local_rotations);
  out.local_translations = std::move(b->local_translations);
  return out;
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
  c.live_frames_over_rate = s.live_frames_over_rate();
  c.live_edit_replays = s.live_edit_replays();
  c.live_marker_points_missing = s.live_marker_points_missing();
  c.live_marker_parts_held = s.live_marker_parts_held();
  c.live_marker_points_outliers = s.live_marker_points_outliers();
  c.live_marker_frames_unsolved = s.live_marker_frames_unsolved();
  c.multicast_frames_sent = s.multicast_frames_sent();
  c.frames_sent_total = s.frames_sent_total();
  c.frames_dropped_total = s.frames_dropped_total();
  c.io_threads = s.io_threads();
  c.io_thread = s.io_thread();
  return c;
}

std::vector<std::string> Client::take_errors() {
  std::lock_guard lock(impl_->mutex);
  std::vector<std::string> out(impl_->async_errors.begin(), impl_->async_errors.end());
  impl_->async_errors.clear();
  return out;
}

}  // namespace gmr::client
