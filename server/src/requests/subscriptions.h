// Subscriptions: one session's subscriptions (docs/protocol.md,
// "Subscriptions"). Each is a target (TCP, UDP or multicast) of a stream the
// StreamRegistry keeps, shared with other subscriptions while they want the
// same bytes and split off when one of them changes alone (pause, seek, a
// view edit). Streams tell it when they end one (SubscriptionEvents).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "live/live_source.h"
#include "requests/session_link.h"
#include "requests/views.h"
#include "streams/stream.h"
#include "streams/targets.h"
#include "transport/udp_publisher.h"

namespace gmr::server {

class Subscriptions final : public SubscriptionEvents {
 public:
  // `udp`: where the session's UDP frames go once registered.
  Subscriptions(SessionLink& link, const Views& views, std::shared_ptr<UdpPublisher::Registration> udp_endpoint)
      : link_(link), views_(views), udp_(std::move(udp_endpoint)) {}
  // What the targets hold to report their end: this object, under its
  // session's ownership (they stop when the session goes).
  void set_self(std::weak_ptr<SubscriptionEvents> self) { self_ = std::move(self); }

  Reply subscribe(const pb::Subscribe& r);
  Reply unsubscribe(const pb::Unsubscribe& r);
  Reply pause(const pb::Pause& r);
  Reply resume(const pb::Resume& r);
  Reply seek(const pb::Seek& r);

  // After an edit of view `v`: its subscriptions follow it onto their own
  // streams (a new skeleton is announced first), or end when a subscribed
  // joint is gone.
  void view_changed(const View& v);
  // The subscriptions of view `view_id` end (the view closes).
  void drop_view(std::uint32_t view_id);
  // Every subscription ends (the connection stopped).
  void clear();
  // Subscriptions whose frames go through the connection, and over UDP.
  std::pair<std::size_t, std::size_t> count() const;

  // SubscriptionEvents: a stream ended subscription `id` after `sent` frames.
  void subscription_ended(std::uint32_t id, std::uint64_t sent, const std::string& reason) override;

 private:
  struct Subscription {
    std::uint32_t view_id = 0;
    std::shared_ptr<Stream> stream;
    std::shared_ptr<SubscriptionTarget> target;
    std::vector<std::string> joint_names;  // empty: every joint
    std::uint64_t rate_mhz = 0;            // committed against the send budget
    std::uint32_t skeleton_version = 0;    // of the frames it last got word of
    OutputBasis basis;                     // its conventions (of the rest pose it is sent)
    bool multicast = false;                // frames go to the group with its stream's (pause, seek refused)
    pb::Conventions conventions;           // as asked: the basis again when the view's unit changes
  };

  Subscription* find(std::uint32_t id);
  void drop(std::uint32_t id);
  // The subscription's target out of its stream (a multicast one out of the stream's channel).
  void remove_target(Subscription& s);
  // The subscription's stream, now its alone (split off a shared one).
  std::shared_ptr<Stream> detach(Subscription& s);
  // A new stream of live source `source`: fed by it from now on, starting
  // with its newest frame.
  void attach_live(LiveSource& source, const std::shared_ptr<Stream>& stream);

  SessionLink& link_;
  const Views& views_;
  std::shared_ptr<UdpPublisher::Registration> udp_;
  std::weak_ptr<SubscriptionEvents> self_;
  std::map<std::uint32_t, Subscription> subs_;
  std::uint32_t next_sub_ = 1;
};

}  // namespace gmr::server
