#include "targets.h"

#include "gmr/wire/frames.h"
#include "request_handler.h"

namespace gmr::server {

bool SubscriptionTarget::alive() const {
  const auto h = handler_.lock();
  const auto c = connection_.lock();
  return h && c && !h->stopped() && !c->stopped();
}

void SubscriptionTarget::ended(std::uint64_t sent, const std::string& reason) {
  if (auto h = handler_.lock()) h->subscription_ended(subscription_, sent, reason);
}

void SubscriptionTarget::skipped(std::uint64_t n) {
  dropped_ += n;
  if (auto c = connection_.lock()) c->count_frame_dropped(n);
}

void SubscriptionTarget::late(std::uint64_t n) {
  late_ += n;
  if (auto c = connection_.lock()) c->count_frame_skipped(n);
}

bool TcpTarget::congested() const {
  auto c = connection_.lock();
  return c && c->congested(subscription_);
}

void TcpTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) {
  auto c = connection_.lock();
  if (!c || c->closing()) return;
  // The per-subscriber head (length prefix, ServerMessage tag, ids); the body is shared.
  if (!c->push_frame(subscription_, wire::frame_head_for(view_, subscription_, stream_id, body->size(), true), body,
                     max_age_)) {
    ++dropped_;
  }
}

void UdpTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) {
  auto c = connection_.lock();
  if (!c || c->closing()) return;
  if (!publisher_.send(endpoint_, wire::frame_message_for(view_, subscription_, stream_id, *body))) {
    ++dropped_;
    c->count_udp_frame_dropped();
    return;
  }
  c->count_udp_frame_sent();
}

void MulticastTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) {
  auto c = connection_.lock();
  if (!c || c->closing()) return;
  MulticastChannel& ch = *channel_;
  // Another subscriber of the stream already sent this one.
  if (!ch.last.owner_before(body) && !body.owner_before(ch.last)) return;
  ch.last = body;
  if (!publisher_.send(ch.group, wire::frame_message_for(0, 0, stream_id, *body))) {
    ++dropped_;
    ++ch.dropped;
    return;
  }
  ++ch.sent;
  if (ch.total_sent != nullptr) ++*ch.total_sent;
}

}  // namespace gmr::server
