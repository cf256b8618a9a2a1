#include "requests/subscriptions.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>

#include "gmr/wire/convert.h"
#include "gmr/wire/framing.h"

namespace gmr::server {

namespace {

Refusal unknown_subscription(std::uint32_t id) {
  return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown subscription " + std::to_string(id)};
}

}  // namespace

Reply Subscriptions::subscribe(const pb::Subscribe& r) {
  const View* v = views_.find(r.view_id());
  if (!v) return unknown_view(r.view_id());
  if (auto why = link_.services.catalog.stale(*v->content()); !why.empty()) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, why};
  }
  const Motion& m = v->motion();
  const ServerConfig& cfg = link_.services.cfg;
  if (subs_.size() >= cfg.max_subscriptions_per_connection) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "at most " + std::to_string(cfg.max_subscriptions_per_connection) + " subscriptions per connection"};
  }
  Stream::Settings settings;
  Stream::Schedule& s = settings.schedule;
  // A live view plays its source's frames as they come: no range, loop,
  // speed or rate of its own (docs/protocol.md, "Live sources").
  std::shared_ptr<LiveSource> source;
  if (v->live()) {
    source = v->live_source();
    if (!source || source->ended()) {
      return Refusal{pb::ERROR_CODE_NOT_FOUND, "the live source '" + v->motion_name() + "' has ended"};
    }
  }
  s.start = source ? 0 : r.start_frame();
  s.end = source ? 1 : r.end_frame() == 0 ? static_cast<std::uint32_t>(m.frame_count) : r.end_frame();
  if (!(s.start < s.end && s.end <= m.frame_count)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "frames [" + std::to_string(s.start) + ", " + std::to_string(s.end) +
                                                   ") are not within the motion's " + std::to_string(m.frame_count) +
                                                   " frames"};
  }
  s.loop = r.loop();
  s.speed = r.speed() == 0.0 ? 1.0 : r.speed();
  if (!(std::isfinite(s.speed) && s.speed >= kMinSpeed && s.speed <= kMaxSpeed)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "speed " + std::to_string(r.speed()) + " is not within [" +
                                                   std::to_string(kMinSpeed) + ", " + std::to_string(kMaxSpeed) + "]"};
  }
  s.rate = source ? 1.0 / source->frame_time() : r.rate_hz() == 0.0 ? s.speed / m.frame_time : r.rate_hz();
  if (source) {
    s.loop = false;
    s.speed = 1.0;
  }
  if (!(std::isfinite(s.rate) && s.rate >= kMinRateHz && s.rate <= kMaxRateHz)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST,
                   "output rate " + std::to_string(s.rate) + " Hz" +
                       (r.rate_hz() == 0.0 ? std::string(" (the motion's rate times speed)") : std::string()) +
                       " is not within [" + std::to_string(kMinRateHz) + ", " + std::to_string(kMaxRateHz) + "] Hz"};
  }
  s.skip_repeats = r.skip_repeats();
  // proto3 keeps enum values it does not know: refuse them rather than guess.
  if (!pb::Transport_IsValid(r.transport()) || !pb::Precision_IsValid(r.precision())) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "unknown transport " + std::to_string(r.transport()) + " or precision " +
                                                   std::to_string(r.precision()) +
                                                   " (this server speaks protocol version " +
                                                   std::to_string(wire::kProtocolVersion) + ")"};
  }
  const bool use_udp = r.transport() == pb::TRANSPORT_UDP;
  const bool use_multicast = r.transport() == pb::TRANSPORT_MULTICAST;
  if (use_multicast && !link_.services.multicast.group) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   "this server sends no multicast (gmr-server --multicast-group): subscribe over TCP or UDP"};
  }
  if (use_udp && !udp_->endpoint) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   "UDP transport: register this connection's UDP endpoint first (send the session token to UDP port " +
                       std::to_string(link_.services.udp.port()) + ")"};
  }
  if (use_multicast && r.paused()) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST,
                   "a multicast subscription follows its shared stream: it cannot start paused (subscribe over TCP or "
                   "UDP to play on your own)"};
  }
  const std::vector<std::string> names(r.joints().begin(), r.joints().end());
  auto joints = views_.resolve_joints(*v, names);
  if (!joints.ok()) return Refusal{pb::ERROR_CODE_NOT_FOUND, joints.error().message};
  auto basis = output_basis_of(r.conventions(), link_.services.catalog.metres_per_unit(*v));
  if (!basis.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, basis.error().message};
  // Its targets hold the connection (targets.h).
  const auto conn = link_.connection();
  if (!conn) return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, "the connection is closing"};
  settings.joints = std::move(joints).value();
  settings.orientations = r.orientations();
  settings.local_transforms = r.local_transforms();
  settings.basis = *basis;
  settings.float64 = r.precision() == pb::PRECISION_FLOAT64;
  settings.max_catch_up = cfg.max_catch_up;

  // Streams with the same content and schedule can share one FK and one
  // encoding per tick.
  // A live source's serial keeps a later source of the same name apart.
  const std::string shown = source ? v->motion_name() + "#live" + std::to_string(source->serial()) : v->motion_name();
  // Multicast is for shared streams: one send per frame for all their subscribers.
  const std::string key = r.shared() || use_multicast ? StreamRegistry::share_key(shown, *v->content(), settings) : "";
  // One that starts paused gets a stream of its own, as a pause gives one: a
  // running stream does not wait for it, and nobody joins it (nor does it
  // take a running stream's place under its key).
  std::shared_ptr<Stream> stream = key.empty() || r.paused() ? nullptr : link_.services.streams.find_running(key);
  const bool joined = stream != nullptr;
  // Admission: what all subscriptions cost stays within what the server can
  // send (docs/protocol.md, "Admission"), each counted by its kind. Committed from here on.
  using Kind = Admission::SendKind;
  const Kind kind = use_multicast ? Kind::kMulticast
                    : joined      ? (use_udp ? Kind::kSharedUdp : Kind::kSharedTcp)
                                  : (use_udp ? Kind::kOwnUdp : Kind::kOwnTcp);
  const std::uint64_t rate_mhz = Admission::cost_mhz(s.rate, kind);
  if (auto refused = link_.services.admission.commit_rate(s.rate, rate_mhz)) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, std::move(*refused)};
  }
  if (!stream) {
    stream = link_.services.streams.create(v->content(), settings, r.paused() ? std::string() : key);
    if (source) stream->set_live();
  }

  const std::uint32_t id = next_sub_++;
  std::shared_ptr<SubscriptionTarget> target;
  std::shared_ptr<MulticastTarget> member;
  if (use_multicast) {
    member = std::make_shared<MulticastTarget>(self_, conn, id, v->id(),
                                               link_.services.multicast.channel(*stream, link_.services.udp));
    target = member;
  } else if (use_udp) {
    target = std::make_shared<UdpTarget>(self_, conn, id, v->id(), link_.services.udp, udp_);
  } else {
    target = std::make_shared<TcpTarget>(self_, conn, id, v->id());
  }
  target->set_max_age(r.max_staleness_ms() == 0 ? std::chrono::milliseconds(cfg.default_max_staleness)
                                                : std::chrono::milliseconds(r.max_staleness_ms()));
  if (member) {
    member->channel()->join(member, r.max_frames());
  } else {
    stream->add(target, r.max_frames());
  }
  subs_[id] =
      Subscription{v->id(),        stream,        target,         names, rate_mhz, v->content()->skeleton_version,
                   settings.basis, use_multicast, r.conventions()};
  if (!joined) {
    if (r.paused()) {
      stream->start_paused();
    } else {
      stream->start();
    }
    if (source) attach_live(*source, stream);
  }

  pb::ServerMessage out;
  auto* sub = out.mutable_subscribed();
  sub->set_subscription_id(id);
  sub->set_view_id(v->id());
  sub->set_skeleton_version(v->content()->skeleton_version);
  for (int j : settings.joints) sub->add_joints(static_cast<std::uint32_t>(j));
  sub->set_rate_hz(s.rate);
  sub->set_stream_id(stream->id());
  sub->set_joined_running(joined);
  wire::to_proto(v->motion(), settings.basis, *sub->mutable_skeleton());
  if (v->content()->relative_to >= 0) sub->set_relative_to(v->motion().skeleton.joint(v->content()->relative_to).name);
  if (use_multicast) {
    const auto& group = *link_.services.multicast.group->endpoint;
    sub->set_multicast_group(group.address().to_string() + ":" + std::to_string(group.port()));
  }
  spdlog::debug("conn {}: subscription {} on view {} (stream {}, {}, {} Hz)", link_.connection_id, id, v->id(),
                stream->id(),
                use_multicast ? "multicast"
                : use_udp     ? "UDP"
                              : "TCP",
                s.rate);
  return out;
}

Reply Subscriptions::unsubscribe(const pb::Unsubscribe& r) {
  if (!find(r.subscription_id())) return unknown_subscription(r.subscription_id());
  drop(r.subscription_id());
  return ack();
}

namespace {
Refusal follows_its_stream(std::uint32_t id) {
  return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                 "subscription " + std::to_string(id) +
                     " is multicast: it follows its shared stream (unsubscribe, and subscribe over TCP or UDP to "
                     "play on your own)"};
}
}  // namespace

Reply Subscriptions::pause(const pb::Pause& r) {
  Subscription* s = find(r.subscription_id());
  if (!s) return unknown_subscription(r.subscription_id());
  if (s->multicast) return follows_its_stream(r.subscription_id());
  detach(*s)->pause();
  return ack();
}

Reply Subscriptions::resume(const pb::Resume& r) {
  Subscription* s = find(r.subscription_id());
  if (!s) return unknown_subscription(r.subscription_id());
  s->stream->resume();
  return ack();
}

Reply Subscriptions::seek(const pb::Seek& r) {
  Subscription* s = find(r.subscription_id());
  if (!s) return unknown_subscription(r.subscription_id());
  if (s->multicast) return follows_its_stream(r.subscription_id());
  if (s->stream->live()) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   "subscription " + std::to_string(r.subscription_id()) + " plays a live source: it cannot seek"};
  }
  const auto& sched = s->stream->schedule();
  if (!(r.frame() >= sched.start && r.frame() < sched.end)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "seek to frame " + std::to_string(r.frame()) +
                                                   ": the subscription plays frames [" + std::to_string(sched.start) +
                                                   ", " + std::to_string(sched.end) + ")"};
  }
  detach(*s)->seek(r.frame());
  return ack();
}

Subscriptions::Subscription* Subscriptions::find(std::uint32_t id) {
  auto it = subs_.find(id);
  return it == subs_.end() ? nullptr : &it->second;
}

std::shared_ptr<Stream> Subscriptions::detach(Subscription& s) {
  auto stream = link_.services.streams.detach(s.stream, s.target.get());
  // A live stream's copy is fed by the same source from now on.
  if (stream != s.stream && stream->live()) {
    const View* v = views_.find(s.view_id);
    if (auto source = v ? v->live_source() : nullptr) source->attach(stream);
  }
  s.stream = std::move(stream);
  return s.stream;
}

void Subscriptions::attach_live(LiveSource& source, const std::shared_ptr<Stream>& stream) {
  source.attach(stream);
  // A subscriber joining a running source starts at its newest frame (after
  // the reply to its Subscribe, which is being written).
  if (source.frames() > 0) {
    net::post(link_.services.io, [weak_stream = std::weak_ptr<Stream>(stream), weak_source = source.weak_from_this()] {
      auto s = weak_stream.lock();
      auto l = weak_source.lock();
      if (s && l) l->send_newest(*s);
    });
  }
}

void Subscriptions::remove_target(Subscription& s) {
  if (!s.multicast) {
    s.stream->remove(s.target.get());
    return;
  }
  // A member of its stream's channel; the channel leaves the stream with its last member.
  const auto& channel = static_cast<const MulticastTarget&>(*s.target).channel();
  channel->leave(static_cast<const MulticastTarget*>(s.target.get()));
  if (channel->members() == 0) s.stream->remove(channel.get());
}

void Subscriptions::drop(std::uint32_t id) {
  auto it = subs_.find(id);
  if (it == subs_.end()) return;
  Subscription& s = it->second;
  remove_target(s);
  if (s.stream->idle()) s.stream->stop();
  if (auto c = link_.connection()) c->discard_frames(id);
  link_.services.admission.release_rate(s.rate_mhz);
  subs_.erase(it);
}

void Subscriptions::view_changed(const View& v) {
  std::vector<std::pair<std::uint32_t, std::string>> ended;
  for (auto& [id, sub] : subs_) {
    if (sub.view_id != v.id()) continue;
    auto joints = views_.resolve_joints(v, sub.joint_names);
    if (!joints.ok()) {
      ended.emplace_back(id, "the view changed: " + joints.error().message);
      continue;
    }
    if (sub.multicast) {  // its stream's content is shared by others: it cannot follow alone
      ended.emplace_back(id, "the view changed: a multicast subscription follows its shared stream (subscribe again)");
      continue;
    }
    // A retarget may change the unit (a rig in its own): the same conventions from the new one.
    auto basis = output_basis_of(sub.conventions, link_.services.catalog.metres_per_unit(v));
    if (!basis.ok()) {
      ended.emplace_back(id, "the view changed: " + basis.error().message);
      continue;
    }
    sub.basis = *basis;
    // The new skeleton goes out before any frame of its version (replies
    // and pushes are written before waiting frames, connection.h), and
    // after every frame of the old one: those still waiting go first.
    if (v.content()->skeleton_version != sub.skeleton_version) {
      sub.skeleton_version = v.content()->skeleton_version;
      if (auto conn = link_.connection()) conn->send_frames_now(id);
      pb::ServerMessage m;
      auto* c = m.mutable_skeleton_changed();
      c->set_subscription_id(id);
      c->set_view_id(v.id());
      c->set_skeleton_version(sub.skeleton_version);
      wire::to_proto(v.motion(), sub.basis, *c->mutable_skeleton());
      for (int j : *joints) c->add_joints(static_cast<std::uint32_t>(j));
      const int viewer = v.content()->relative_to;
      if (viewer >= 0) c->set_relative_to(v.motion().skeleton.joint(viewer).name);
      link_.send(m);
    }
    detach(sub)->set_content(v.content(), std::move(joints).value(), sub.basis);
  }
  for (auto& [id, reason] : ended) {
    pb::ServerMessage m;
    m.mutable_subscription_ended()->set_subscription_id(id);
    m.mutable_subscription_ended()->set_reason(reason);
    drop(id);
    link_.send(m);
  }
}

void Subscriptions::subscription_ended(std::uint32_t id, std::uint64_t sent, const std::string& reason) {
  auto it = subs_.find(id);
  if (it == subs_.end()) return;
  Subscription& s = it->second;
  pb::ServerMessage m;
  m.mutable_subscription_ended()->set_subscription_id(id);
  m.mutable_subscription_ended()->set_frames_sent(sent);
  // The frames still waiting go out before the end notice.
  auto c = link_.connection();
  const std::uint64_t stale = c ? c->end_frames(id) : 0;
  m.mutable_subscription_ended()->set_frames_dropped(s.target->dropped() + stale);
  m.mutable_subscription_ended()->set_frames_stale(stale);
  m.mutable_subscription_ended()->set_frames_skipped(s.target->late_skipped());
  m.mutable_subscription_ended()->set_reason(reason);
  remove_target(s);
  link_.services.admission.release_rate(s.rate_mhz);
  subs_.erase(it);
  link_.send(m);
}

void Subscriptions::drop_view(std::uint32_t view_id) {
  std::vector<std::uint32_t> ids;
  for (const auto& [id, sub] : subs_) {
    if (sub.view_id == view_id) ids.push_back(id);
  }
  for (auto id : ids) drop(id);
}

void Subscriptions::clear() {
  for (auto& [id, sub] : subs_) {
    remove_target(sub);
    link_.services.admission.release_rate(sub.rate_mhz);
  }
  subs_.clear();
}

std::pair<std::size_t, std::size_t> Subscriptions::count() const {
  std::size_t over_udp = 0;
  for (const auto& [id, s] : subs_) over_udp += dynamic_cast<const UdpTarget*>(s.target.get()) != nullptr ? 1 : 0;
  return {subs_.size() - over_udp, over_udp};
}

}  // namespace gmr::server
