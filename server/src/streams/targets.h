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
#include <string>

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
};

// Frames go into the connection's outbox (latest wins per subscription).
class TcpTarget final : public SubscriptionTarget {
 public:
  using SubscriptionTarget::SubscriptionTarget;
  void deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) override;
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
  void deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) override;
  bool congested() const override { return publisher_.congested(*endpoint_); }

 private:
  UdpPublisher& publisher_;
  std::shared_ptr<UdpPublisher::Registration> endpoint_;
};

// One shared stream's frames to the multicast group: once per frame, however
// many of its subscribers chose multicast (docs/protocol.md, "Multicast").
struct MulticastChannel {
  std::shared_ptr<UdpPublisher::Registration> group;
  std::weak_ptr<const std::string> last;  // the body sent last (owner-compared: never a reused address)
  std::uint64_t sent = 0, dropped = 0;
  std::uint64_t* total_sent = nullptr;  // the server's count, all channels
};

// The multicast group (cfg.multicast_group) and each shared stream's channel
// to it, by stream id.
struct MulticastGroup {
  std::shared_ptr<UdpPublisher::Registration> group;  // null: no multicast
  std::map<std::uint64_t, std::weak_ptr<MulticastChannel>> channels;
  std::uint64_t frames_sent = 0;  // all channels
  // The channel of stream `stream_id` (made when none is open); forgets
  // channels no subscriber holds any more.
  std::shared_ptr<MulticastChannel> channel(std::uint64_t stream_id);
};

// A subscriber of a shared stream over multicast: its frames are the
// channel's; its end, skips and drops are its own, told over its connection.
class MulticastTarget final : public SubscriptionTarget {
 public:
  MulticastTarget(std::weak_ptr<SubscriptionEvents> events, std::shared_ptr<Outbox> connection,
                  std::uint32_t subscription, std::uint32_t view, UdpPublisher& publisher,
                  std::shared_ptr<MulticastChannel> channel)
      : SubscriptionTarget(std::move(events), std::move(connection), subscription, view),
        publisher_(publisher),
        channel_(std::move(channel)) {}
  void deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body) override;
  bool congested() const override { return publisher_.congested(*channel_->group); }
  const std::shared_ptr<MulticastChannel>& channel() const { return channel_; }

 private:
  UdpPublisher& publisher_;
  std::shared_ptr<MulticastChannel> channel_;
};

}  // namespace gmr::server
