// RequestHandler: one connection's views and subscriptions. It answers each
// request with a reply or a refusal (a value carrying the protocol's error
// code, never an exception), and sends nothing itself but through its
// Connection. It reaches the rest of the server only through Services
// (services.h). Adding a request: a case in dispatch() and a method in the
// file of its family: request_handler.cpp (the session: Hello, roles,
// dispatch, answers, statistics), views.cpp (views, edits, queries),
// subscriptions.cpp, publications.cpp (live sources).
//
// Subscriptions are targets of streams (targets.h): a TcpTarget puts frames
// into this connection's outbox, a UdpTarget sends them to the registered
// UDP endpoint through the UdpPublisher.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "admission.h"
#include "gmr/server/view.h"
#include "gmr/view/conventions.h"
#include "requests/services.h"
#include "streams/stream.h"
#include "streams/targets.h"
#include "transport/connection.h"

namespace gmr::server {

// The output basis a request's conventions ask for (docs/protocol.md,
// "Conventions"): an error message for unknown presets or bad axes/units.
// motion_metres_per_unit: the library's word on the motion's unit (0: unknown),
// used when the request gives none.
Result<OutputBasis> output_basis_of(const pb::Conventions& c, double motion_metres_per_unit);


class RequestHandler : public Connection::Handler,
                       public SubscriptionEvents,
                       public SessionInfo,
                       public std::enable_shared_from_this<RequestHandler> {
 public:
  // `outbox`: the client's transport (a Connection, or a test's recorder).
  RequestHandler(Services& services, const std::shared_ptr<Outbox>& outbox);
  // Takes a UDP session token (needs the handler owned by a shared_ptr).
  void start();

  void on_message(const std::string& body) override;
  void on_stop() override;

  // SubscriptionEvents: a stream ended subscription `id` after `sent` frames.
  void subscription_ended(std::uint32_t id, std::uint64_t sent, const std::string& reason) override;
  // The connection's UDP endpoint was registered (or moved).
  void udp_registered(const udp::endpoint& endpoint);

  const std::shared_ptr<UdpPublisher::Registration>& udp() const { return udp_; }
  // SessionInfo.
  std::size_t view_count() const override { return views_.size(); }
  std::pair<std::size_t, std::size_t> subscription_count() const override;
  bool has_udp_endpoint() const override { return udp_->endpoint.has_value(); }
  bool stopped() const { return stopped_; }

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
  };

  void send(const pb::ServerMessage& m);
  Reply dispatch(const pb::ClientMessage& m, Clock::time_point began);
  // Sends the reply (or the refusal) to request `request_id`, and counts it.
  void answer(std::uint64_t request_id, std::string_view kind, Clock::time_point began, Reply reply);
  Reply hello(const pb::Hello& r);
  // Requests only a 'control' connection may make (docs/security.md).
  static bool needs_control(pb::ClientMessage::BodyCase request);
  // The request's kind for metrics: its ClientMessage field's name.
  static std::string_view request_kind(const pb::ClientMessage& m);

  Reply stats();

  // views.cpp: the library and views.
  Reply list_motions() const;
  Reply get_skeleton(const pb::GetSkeleton& r) const;
  Reply create_view(const pb::CreateView& r);
  Reply close_view(const pb::CloseView& r);
  // A structural edit (gmr/server/view.h's ViewEdit): computed at once on a
  // short motion, else on the server's edit thread while this connection's
  // requests wait unread (the reply then comes from there; dispatch gives
  // no reply). `decorate` adds what the edit reports to the reply.
  using EditDecoration = void (*)(const EditReport&, pb::ViewInfo&);
  Reply edit_view(const pb::ClientMessage& req, Clock::time_point began, std::uint32_t view_id,
                  const std::function<Result<ViewEdit>(const View&)>& make, EditDecoration decorate = nullptr);
  // Installs an edit's result under the view budget; the reply.
  Reply commit_edit(std::uint32_t view_id, const ViewEdit& edit, Result<std::shared_ptr<const ViewContent>> next,
                    EditDecoration decorate);
  Reply set_coordinates(const pb::SetCoordinates& r);
  Reply query(const pb::QueryFrames& r) const;
  void forget_view(const View& v);

  // publications.cpp: live sources (live_source.h) published by this connection.
  Reply publish(const pb::Publish& r);
  Reply publish_frame(const pb::PublishFrame& r);
  Reply unpublish(const pb::Unpublish& r);
  void end_publication(std::uint32_t id, const std::string& reason);

  // subscriptions.cpp: subscriptions and their streams.
  Reply subscribe(const pb::Subscribe& r);
  Reply unsubscribe(const pb::Unsubscribe& r);
  Reply pause(const pb::Pause& r);
  Reply resume(const pb::Resume& r);
  Reply seek(const pb::Seek& r);
  // After a view edit: its subscriptions follow it onto their own streams,
  // or end when a subscribed joint is gone.
  void view_changed(const View& v);
  void drop_subscription(std::uint32_t id);
  // The subscription's stream, now its alone (split off a shared one).
  std::shared_ptr<Stream> detach(Subscription& s);
  // A new stream of live source `source`: fed by it from now on, starting
  // with its newest frame.
  void attach_live(LiveSource& source, const std::shared_ptr<Stream>& stream);

  // Lookups: a refusal (NOT_FOUND) names what is missing.
  View* find_view(std::uint32_t id) const;
  Subscription* find_subscription(std::uint32_t id);
  Result<std::vector<int>> resolve_joints(const View& v, const std::vector<std::string>& names) const;
  pb::ViewInfo view_info(const View& v) const;

  Services& services_;
  std::weak_ptr<Outbox> connection_;
  std::uint64_t connection_id_ = 0;
  wire::UdpToken token_{};
  std::shared_ptr<UdpPublisher::Registration> udp_;
  bool handshaked_ = false;
  Role role_ = Role::kNone;  // set by Hello
  bool stopped_ = false;
  bool edit_deferred_ = false;  // the request being dispatched is answered from the edit thread
  LogLimiter log_limit_;  // lines this client's bad requests may put in the log

  std::map<std::uint32_t, std::unique_ptr<View>> views_;
  std::uint64_t view_bytes_ = 0;  // Catalog::owned_bytes of views_, also counted in Admission
  std::uint32_t next_view_ = 1;
  std::map<std::uint32_t, Subscription> subs_;
  std::uint32_t next_sub_ = 1;
  std::map<std::uint32_t, std::shared_ptr<LiveSource>> publications_;
  std::map<const LiveSource*, std::string> recordings_;  // of publications_, those recorded: the file
  std::uint32_t next_publication_ = 1;
};

}  // namespace gmr::server
