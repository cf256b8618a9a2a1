#include "client_impl.h"

namespace gmr::client {

namespace {

// How many frames an ended subscription's client gets: those the server
// counted against it, less those it dropped (slow client, staleness) or
// skipped (late server).
std::uint64_t frames_to_come(const SubscriptionEnd& e) {
  const std::uint64_t gone = e.frames_dropped + e.frames_skipped;
  return e.frames_sent > gone ? e.frames_sent - gone : 0;
}

SubscriptionEnd end_of(const pb::SubscriptionEnded& e) {
  return SubscriptionEnd{e.subscription_id(), e.frames_sent(),    e.frames_dropped(),
                         e.reason(),          e.frames_skipped(), e.frames_stale()};
}

}  // namespace

std::string Client::Impl::bad_joints(const google::protobuf::RepeatedField<std::uint32_t>& joints,
                                     std::size_t skeleton_size) {
  if (skeleton_size == 0) return {};
  for (const std::uint32_t j : joints) {
    if (j >= skeleton_size) {
      return "joint index " + std::to_string(j) + " of a skeleton of " + std::to_string(skeleton_size) + " joints";
    }
  }
  return {};
}

void Client::Impl::on_message(const pb::ServerMessage& m, bool via_udp) {
  if (m.has_frame()) {
    if (auto sub = deliver_frame(wire::frame_fields(m.frame()), via_udp, [&] { return m; }))
      finish_ending(m.frame().subscription_id(), sub, false);
    return;
  }
  if (m.request_id() != 0) {
    on_answer(m);
  } else {
    on_push(m);
  }
}

bool Client::Impl::take_message(std::string_view message, bool via_udp) {
  wire::FrameFields f;
  if (wire::read_frame_message(message, f)) {
    auto held = [message] {
      pb::ServerMessage m;
      m.ParseFromArray(message.data(), static_cast<int>(message.size()));  // as read_frame_message read it
      return m;
    };
    if (auto sub = deliver_frame(f, via_udp, held)) finish_ending(f.subscription_id, sub, false);
    return true;
  }
  pb::ServerMessage m;
  if (!m.ParseFromArray(message.data(), static_cast<int>(message.size()))) return false;
  if (!via_udp || m.has_frame()) on_message(m, via_udp);
  return true;
}

std::shared_ptr<Client::Impl::Sub> Client::Impl::deliver_frame(const wire::FrameFields& f, bool via_udp,
                                                               const std::function<pb::ServerMessage()>& held) {
  std::shared_ptr<Sub> sub;
  std::size_t values = 0;  // what the frame must carry (0: not stated)
  {
    std::lock_guard lock(mutex);
    (via_udp ? counters.frames_udp : counters.frames_tcp)++;
    if (auto it = subs.find(f.subscription_id); it != subs.end()) {
      sub = it->second;
      values = sub->values;
      ++sub->arrived;
      if (f.skeleton_version != sub->skeleton_version) {
        ++counters.frames_other_skeleton;
        return sub;
      }
    } else if (subscribes_in_flight > 0) {
      if (early_frames.size() == kMaxEarlyFrames) early_frames.pop_front();
      early_frames.emplace_back(held(), via_udp);
      (via_udp ? counters.frames_udp : counters.frames_tcp)--;  // counted when replayed
      return nullptr;
    }
  }
  if (!sub || !sub->on_frame) return sub;
  const std::int64_t received = now_ns();
  // Older than its bound (it waited in the kernel's buffers while this
  // client was not reading): dropped, counted.
  if (sub->max_age_ns > 0 && received + hello.clock_offset_ns - f.server_send_time_ns > sub->max_age_ns) {
    std::lock_guard lock(mutex);
    ++counters.frames_stale;
    return sub;
  }
  ReceivedFrame& r = sub->frame;
  if (!wire::unpack_frame(f, r).ok() || (values != 0 && r.positions.size() != values)) {
    std::lock_guard lock(mutex);
    ++counters.frames_malformed;
    return sub;
  }
  r.receive_time_ns = received;
  r.udp = via_udp;
  sub->on_frame(r);
  return sub;
}

void Client::Impl::finish_ending(std::uint32_t id, const std::shared_ptr<Sub>& sub, bool now) {
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

void Client::Impl::on_push(const pb::ServerMessage& m) {
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
    // A change whose joints do not fit its skeleton is not taken: the frames
    // of its version are then dropped as another skeleton's.
    const bool usable = sk.ok() && sk->size() > 0 && bad_joints(c.joints(), sk->size()).empty();
    if (sub && usable) {
      std::lock_guard lock(mutex);
      sub->skeleton_version = c.skeleton_version();
      sub->values = c.joints_size() > 0 ? static_cast<std::size_t>(c.joints_size()) : sk->size();
    } else if (sub) {
      std::lock_guard lock(mutex);
      ++counters.frames_malformed;
    }
    if (sub && sub->on_skeleton && usable) {
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

}  // namespace gmr::client
