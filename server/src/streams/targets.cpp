#include "streams/targets.h"

#include "gmr/wire/frames.h"

namespace gmr::server {

bool SubscriptionTarget::alive() const { return !connection_->stopped() && !events_.expired(); }

void SubscriptionTarget::ended(std::uint64_t sent, const std::string& reason) {
  if (auto e = events_.lock()) e->subscription_ended(subscription_, sent, reason);
}

void SubscriptionTarget::skipped(std::uint64_t n) {
  dropped_ += n;
  connection_->count_frame_dropped(n);
}

void SubscriptionTarget::late(std::uint64_t n) {
  late_ += n;
  connection_->count_frame_skipped(n);
}

bool TcpTarget::congested() const { return connection_->congested(subscription_); }

void TcpTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) {
  // The per-subscriber head (length prefix, ServerMessage tag, ids); the
  // body is shared. A closing connection takes nothing (and says it kept it).
  if (!connection_->push_frame(subscription_, wire::frame_head_for(view_, subscription_, stream_id, body->size(), true),
                               body, max_age_)) {
    ++dropped_;
  }
}

void UdpTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) {
  // The head and the shared body go into the datagrams as they are: no copy
  // of the whole message per subscriber.
  if (!publisher_.send_frame(endpoint_, wire::frame_head_for(view_, subscription_, stream_id, body->size(), false),
                             *body)) {
    ++dropped_;
    connection_->count_udp_frame_dropped();
    return;
  }
  connection_->count_udp_frame_sent();
}

void MulticastTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) {
  MulticastChannel& ch = *channel_;
  // Another subscriber of the stream already sent this one.
  if (!ch.last.owner_before(body) && !body.owner_before(ch.last)) return;
  ch.last = body;
  if (!publisher_.send_frame(ch.group, wire::frame_head_for(0, 0, stream_id, body->size(), false), *body)) {
    ++dropped_;
    ++ch.dropped;
    return;
  }
  ++ch.sent;
  if (ch.total_sent != nullptr) ++*ch.total_sent;
}

std::shared_ptr<MulticastChannel> MulticastGroup::channel(std::uint64_t stream_id) {
  auto& slot = channels[stream_id];
  auto c = slot.lock();
  if (!c) {
    c = std::make_shared<MulticastChannel>();
    c->group = group;
    c->total_sent = &frames_sent;
    slot = c;
  }
  std::erase_if(channels, [](const auto& e) { return e.second.expired(); });
  return c;
}

}  // namespace gmr::server
