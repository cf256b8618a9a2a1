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

const wire::FrameHead& SubscriptionTarget::head_for(std::uint64_t stream_id, std::size_t body_size,
                                                    bool length_prefix) {
  if (stream_id != head_stream_ || body_size != head_body_size_) {
    head_ = wire::frame_head_for(view_, subscription_, stream_id, body_size, length_prefix);
    head_stream_ = stream_id;
    head_body_size_ = body_size;
  }
  return head_;
}

bool TcpTarget::congested() const { return connection_->congested(subscription_); }

void TcpTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body,
                        std::chrono::steady_clock::time_point made) {
  // The per-subscriber head (length prefix, ServerMessage tag, ids); the
  // body is shared. A closing connection takes nothing (and says it kept it).
  if (!connection_->push_frame(subscription_, head_for(stream_id, body->size(), true), body, max_age_, made)) {
    ++dropped_;
  }
}

void UdpTarget::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body,
                        std::chrono::steady_clock::time_point made) {
  // The head and the shared body go into the datagrams as they are: no copy
  // of the whole message per subscriber.
  if (!publisher_.send_frame(endpoint_, head_for(stream_id, body->size(), false).view(), *body)) {
    ++dropped_;
    connection_->count_udp_frame_dropped();
    return;
  }
  connection_->count_udp_frame_sent(std::chrono::steady_clock::now() - made);
}

void MulticastChannel::join(const std::shared_ptr<MulticastTarget>& member, std::uint64_t max_frames) {
  if (member->slot_ != static_cast<std::size_t>(-1)) return;
  member->slot_ = members_.size();
  Member m{member, ticks_, dropped_, late_, std::nullopt};
  if (max_frames != 0) m.deadline = deadlines_.emplace(ticks_ + max_frames, member.get());
  members_.push_back(std::move(m));
}

std::shared_ptr<MulticastTarget> MulticastChannel::remove_slot(std::size_t slot) {
  Member m = std::move(members_[slot]);
  if (slot + 1 != members_.size()) {
    members_[slot] = std::move(members_.back());
    members_[slot].target->slot_ = slot;
  }
  members_.pop_back();
  if (m.deadline) deadlines_.erase(*m.deadline);
  m.target->slot_ = static_cast<std::size_t>(-1);
  if (const auto d = dropped_ - m.dropped_at_join; d > 0) m.target->skipped(d);
  if (const auto l = late_ - m.late_at_join; l > 0) m.target->late(l);
  return std::move(m.target);
}

void MulticastChannel::leave(const MulticastTarget* member) {
  if (member->slot_ < members_.size() && members_[member->slot_].target.get() == member) remove_slot(member->slot_);
}

void MulticastChannel::deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body,
                               std::chrono::steady_clock::time_point) {
  if (publisher_.send_frame(group_, wire::frame_head_for(0, 0, stream_id, body->size(), false).view(), *body)) {
    ++sent_;
    if (total_sent_ != nullptr) ++*total_sent_;
  } else {
    ++dropped_;
  }
  advance(1);
}

void MulticastChannel::skipped(std::uint64_t n) {
  dropped_ += n;
  advance(n);
}

void MulticastChannel::late(std::uint64_t n) {
  late_ += n;
  advance(n);
}

void MulticastChannel::advance(std::uint64_t n) {
  ticks_ += n;
  // The ones whose max_frames came: out first, then told (ending one may
  // make its owner leave, or drop others).
  std::vector<std::pair<std::shared_ptr<MulticastTarget>, std::uint64_t>> ended;
  while (!deadlines_.empty() && deadlines_.begin()->first <= ticks_) {
    const auto [deadline, t] = *deadlines_.begin();
    // Its max_frames, even when a jump of several ticks passed it (as the
    // stream counts its own targets).
    const std::uint64_t frames = deadline - members_[t->slot_].ticks_at_join;
    ended.emplace_back(remove_slot(t->slot_), frames);
  }
  for (auto& [t, frames] : ended) {
    if (t->alive()) t->ended(frames, "max_frames reached");
  }
  const auto now = Clock::now();
  if (now - last_sweep_ < kSweepEvery) return;
  last_sweep_ = now;
  for (std::size_t i = members_.size(); i-- > 0;) {
    if (!members_[i].target->alive()) remove_slot(i);
  }
}

void MulticastChannel::ended(std::uint64_t, const std::string& reason) {
  std::vector<std::pair<std::shared_ptr<MulticastTarget>, std::uint64_t>> all;
  all.reserve(members_.size());
  while (!members_.empty()) {
    const std::uint64_t frames = ticks_ - members_.back().ticks_at_join;
    all.emplace_back(remove_slot(members_.size() - 1), frames);
  }
  for (auto& [t, frames] : all) {
    if (t->alive()) t->ended(frames, reason);
  }
}

std::shared_ptr<MulticastChannel> MulticastGroup::channel(Stream& stream, UdpPublisher& publisher) {
  std::erase_if(channels, [](const auto& e) { return e.second.expired(); });
  auto& slot = channels[stream.id()];
  auto c = slot.lock();
  if (!c) {
    c = std::make_shared<MulticastChannel>(publisher, group, &frames_sent);
    slot = c;
    stream.add(c, 0);
  }
  return c;
}

}  // namespace gmr::server
