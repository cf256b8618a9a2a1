#include "client_impl.h"

namespace gmr::client {

Status Client::register_udp() {
  auto& d = *impl_;
  if (!d.udp_open || d.hello.udp_port == 0) return make_error("the server offers no UDP");
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
  return make_error(d.open ? "the server did not confirm the UDP registration in time"
                           : "not connected: " + d.close_reason);
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
  s->set_paused(o.paused);
  // Zero: no bound, which the wire says with the largest (0 there is the server's default).
  const auto staleness_ms = o.max_staleness.count() <= 0
                                ? std::numeric_limits<std::uint32_t>::max()
                                : static_cast<std::uint32_t>(std::min<std::int64_t>(
                                      o.max_staleness.count(), std::numeric_limits<std::uint32_t>::max()));
  s->set_max_staleness_ms(staleness_ms);
  auto sub = std::make_shared<Impl::Sub>(
      Impl::Sub{std::move(on_frame), std::move(on_end), std::move(on_skeleton),
                o.max_staleness.count() > 0 ? std::int64_t{o.max_staleness.count()} * 1000000 : 0});
  // Registered on the I/O thread as the reply is read, before any frame.
  {
    std::lock_guard lock(impl_->mutex);
    ++impl_->subscribes_in_flight;
  }
  auto replied = std::make_shared<std::atomic<bool>>(false);
  auto r = impl_->expect(
      m, pb::ServerMessage::kSubscribed, [impl = impl_.get(), sub, replied](const pb::ServerMessage& reply) {
        std::deque<std::pair<pb::ServerMessage, bool>> replay;
        {
          std::lock_guard lock(impl->mutex);
          *replied = true;
          --impl->subscribes_in_flight;
          if (reply.has_subscribed()) {
            const auto& sr = reply.subscribed();
            sub->stream_id = sr.stream_id();
            sub->skeleton_version = sr.skeleton_version();
            sub->multicast = !sr.multicast_group().empty();
            sub->values = sr.joints_size() > 0 ? static_cast<std::size_t>(sr.joints_size())
                                               : static_cast<std::size_t>(sr.skeleton().joints_size());
            impl->subs[sr.subscription_id()] = sub;
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
    info.metres_per_unit = sr.skeleton().metres_per_unit();
    if (const std::string why = Impl::bad_joints(sr.joints(), info.skeleton.size()); !why.empty()) {
      (void)unsubscribe(info.id);
      return make_error(ErrorKind::kInvalidData, "the server's subscription names " + why);
    }
  }
  info.relative_to = sr.relative_to();
  info.multicast_group = sr.multicast_group();
  if (!info.multicast_group.empty()) {
    // Joined on the strand, as every socket of this client is used.
    auto joined = std::make_shared<std::promise<Status>>();
    auto done = joined->get_future();
    net::post(impl_->strand,
              [impl = impl_, joined, group = info.multicast_group] { joined->set_value(impl->join_multicast(group)); });
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

}  // namespace gmr::client
