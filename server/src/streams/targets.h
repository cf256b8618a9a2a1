// The two kinds of stream target a subscription can be: frames into the
// connection's TCP outbox, or frames to its registered UDP endpoint. Both
// count their drops (for SubscriptionEnded) and tell their owner (a
// SubscriptionEvents, the requests' side) when the stream ends them.
//
// A target holds its connection (not a weak_ptr: locking one per subscriber
// per tick costs atomic operations on a control block the connection's I/O
// thread shares); the connection drops its handler when it stops, so the
// connection -> handler -> subscription -> target -> connection cycle ends
// there, and alive() reads the connection's stopped flag alone.
#pragma once

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "transport/outbox.h"
#include "streams/stream.h"
#include "transport/udp_publisher.h"

namespace gmr::server {

// What a subscription's owner hears from the stream that ends it (the end
// of the motion, max_frames, a live source ending): the seam through which
// streams reach the requests' side without knowing it.
class SubscriptionEvents {
 public:
  virtual ~SubscriptionEvents() = default;
  // The stream ended subscription `id` after `sent` frames.
  virtual void subscription_ended(std::uint32_t id, std::uint64_t sent, const std::string& reason) = 0;
};

class SubscriptionTarget : public Target {
 public:
  // `connection` is not null. The target lives while `events` does.
  SubscriptionTarget(std::weak_ptr<SubscriptionEvents> events, std::shared_ptr<Outbox> connection,
                     std::uint32_t subscription, std::uint32_t view)
      : events_(std::move(events)), connection_(std::move(connection)), subscription_(subscription), view_(view) {}

  bool alive() const override;
  void ended(std::uint64_t sent, const std::string& reason) override;
  void skipped(std::uint64_t n) override;
  void late(std::uint64_t n) override;

  std::uint32_t subscription() const { return subscription_; }
  // Frames that would wait longer than this in the outbox are dropped (TCP).
  void set_max_age(std::chrono::steady_clock::duration d) { max_age_ = d; }
  std::uint64_t dropped() const { return dropped_; }
  std::uint64_t late_skipped() const { return late_; }

 protected:
  std::weak_ptr<SubscriptionEvents> events_;
  std::shared_ptr<Outbox> connection_;
  std::uint32_t subscription_;
  std::uint32_t view_;
  std::uint64_t dropped_ = 0;
  std::uint64_t late_ = 0;
  std::chrono::steady_clock::duration max_age_{};

  // This subscriber's frame head (frame_head_for) before a body of
  // `body_size` bytes from `stream_id`: made again only when either changes
  // (a shared stream's bodies mostly keep their size from frame to frame).
  const wire::FrameHead& head_for(std::uint64_t stream_id, std::size_t body_size, bool length_prefix);

 private:
  wire::FrameHead head_;
  std::uint64_t head_stream_ = 0;
  std::size_t head_body_size_ = static_cast<std::size_t>(-1);
};

// Frames go into the connection's outbox (latest wins per subscription).
class TcpTarget final : public SubscriptionTarget {
 public:
  using SubscriptionTarget::SubscriptionTarget;
  void deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body,
               std::chrono::steady_clock::time_point made) override;
  bool congested() const override;
};

// Frames go to the connection's registered UDP endpoint, as fragments.
class UdpTarget final : public SubscriptionTarget {
 public:
  UdpTarget(std::weak_ptr<SubscriptionEvents> events, std::shared_ptr<Outbox> connection, std::uint32_t subscription,
            std::uint32_t view, UdpPublisher& publisher, std::shared_ptr<UdpPublisher::Registration> endpoint)
      : SubscriptionTarget(std::move(events), std::move(connection), subscription, view),
        publisher_(publisher),
        endpoint_(std::move(endpoint)) {}
  void deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body,
               std::chrono::steady_clock::time_point made) override;
  bool congested() const override { return publisher_.congested(*endpoint_); }

 private:
  UdpPublisher& publisher_;
  std::shared_ptr<UdpPublisher::Registration> endpoint_;
};

class MulticastTarget;

// One shared stream's frames to the multicast group, once per frame however
// many of its subscribers chose multicast (docs/protocol.md, "Multicast").
// The channel is the stream's one target for all of them, so a tick costs
// the same for one subscriber or ten thousand: it sends once and touches no
// subscriber. Each subscriber's frames, drops and skips are the channel's
// since it joined, settled when it leaves or ends; its max_frames is a
// deadline the channel keeps in order (the earliest checked per frame); and
// subscribers whose connection went are forgotten by a sweep once a second.
class MulticastChannel final : public Target {
 public:
  MulticastChannel(UdpPublisher& publisher, std::shared_ptr<UdpPublisher::Registration> group,
                   std::uint64_t* total_sent)
      : publisher_(publisher), group_(std::move(group)), total_sent_(total_sent) {}

  // `member` gets the channel's frames from the next one on; it ends after
  // `max_frames` (0: no limit).
  void join(const std::shared_ptr<MulticastTarget>& member, std::uint64_t max_frames);
  // `member` leaves (a no-op when it is not a member), its counts settled.
  void leave(const MulticastTarget* member);
  std::size_t members() const { return members_.size(); }
  std::uint64_t sent() const { return sent_; }
  std::uint64_t dropped() const { return dropped_; }

  // As its stream's target: alive while anyone listens.
  bool alive() const override { return !members_.empty(); }
  void deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body,
               std::chrono::steady_clock::time_point made) override;
  bool congested() const override { return publisher_.congested(*group_); }
  void skipped(std::uint64_t n) override;
  void late(std::uint64_t n) override;
  // The stream ended: every member ends with its own count of frames.
  void ended(std::uint64_t sent, const std::string& reason) override;

  static constexpr std::chrono::seconds kSweepEvery{1};

 private:
  using Deadlines = std::multimap<std::uint64_t, MulticastTarget*>;
  struct Member {
    std::shared_ptr<MulticastTarget> target;
    std::uint64_t ticks_at_join = 0, dropped_at_join = 0, late_at_join = 0;
    std::optional<Deadlines::iterator> deadline;
  };
  // Ticks advanced by `n` (each a frame sent, dropped or skipped): members
  // whose max_frames came end; once a second, members whose connection went
  // are forgotten.
  void advance(std::uint64_t n);
  // Member `slot` out of the channel (swapped with the last), its counts
  // settled; the target, to end it.
  std::shared_ptr<MulticastTarget> remove_slot(std::size_t slot);

  UdpPublisher& publisher_;
  std::shared_ptr<UdpPublisher::Registration> group_;
  std::uint64_t* total_sent_;  // the server's count, all channels (may be null)
  std::vector<Member> members_;
  Deadlines deadlines_;  // tick at which a member's max_frames is reached
  std::uint64_t ticks_ = 0, sent_ = 0, dropped_ = 0, late_ = 0;
  Clock::time_point last_sweep_ = Clock::now();
};

// A subscriber of a shared stream over multicast: a member of the stream's
// channel, never a target of the stream itself. Its end, skips and drops are
// its own, told over its connection.
class MulticastTarget final : public SubscriptionTarget {
 public:
  MulticastTarget(std::weak_ptr<SubscriptionEvents> events, std::shared_ptr<Outbox> connection,
                  std::uint32_t subscription, std::uint32_t view, std::shared_ptr<MulticastChannel> channel)
      : SubscriptionTarget(std::move(events), std::move(connection), subscription, view),
        channel_(std::move(channel)) {}
  // The channel sends; a stream never hands this target a frame.
  void deliver(std::uint64_t, const std::shared_ptr<const std::string>&,
               std::chrono::steady_clock::time_point) override {}
  const std::shared_ptr<MulticastChannel>& channel() const { return channel_; }

 private:
  friend class MulticastChannel;
  std::shared_ptr<MulticastChannel> channel_;
  std::size_t slot_ = static_cast<std::size_t>(-1);  // in the channel's members; -1: not a member
};

// The multicast group (cfg.multicast_group) and each shared stream's channel
// to it, by stream id.
struct MulticastGroup {
  std::shared_ptr<UdpPublisher::Registration> group;  // null: no multicast
  std::map<std::uint64_t, std::weak_ptr<MulticastChannel>> channels;
  std::uint64_t frames_sent = 0;  // all channels
  // `stream`'s channel; made, and added to the stream as its target, when
  // none is open. Forgets channels no subscriber holds any more.
  std::shared_ptr<MulticastChannel> channel(Stream& stream, UdpPublisher& publisher);
};

}  // namespace gmr::server
