// RequestHandler: one client's session. It says Hello (the role, from the
// token), dispatches each request to the family that owns its state
// (Views, Subscriptions, Publications, each in its own file), and answers
// with a reply or a refusal (a value carrying the protocol's error code,
// never an exception); it sends nothing but through its connection. It
// reaches the rest of the server only through Services (services.h).
//
// Adding a request: a case in dispatch() and a method in the class of its
// family.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <utility>

#include "admission.h"
#include "gmr/server/auth.h"
#include "gmr/server/view.h"
#include "gmr/wire/udp.h"
#include "requests/off_loop.h"
#include "requests/publications.h"
#include "requests/services.h"
#include "requests/session_link.h"
#include "requests/subscriptions.h"
#include "requests/views.h"
#include "transport/connection.h"

namespace gmr::server {

class RequestHandler : public Connection::Handler,
                       public SessionInfo,
                       public std::enable_shared_from_this<RequestHandler> {
 public:
  // `outbox`: the client's transport (a Connection, or a test's recorder).
  RequestHandler(Services& services, const std::shared_ptr<Outbox>& outbox);
  // Takes a UDP session token (needs the handler owned by a shared_ptr).
  void start();

  void on_message(const std::string& body) override;
  void on_stop() override;

  // The connection's UDP endpoint was registered (or moved).
  void udp_registered(const udp::endpoint& endpoint);

  // SessionInfo.
  std::size_t view_count() const override { return views_.count(); }
  std::pair<std::size_t, std::size_t> subscription_count() const override { return subscriptions_.count(); }
  bool has_udp_endpoint() const override { return udp_->endpoint.has_value(); }

 private:
  Reply dispatch(const pb::ClientMessage& m, Clock::time_point began);
  // Sends the reply (or the refusal) to request `request_id`, and counts it.
  void answer(std::uint64_t request_id, std::string_view kind, Clock::time_point began, Reply reply);
  Reply hello(const pb::Hello& r);
  Reply stats();
  Reply close_view(const pb::CloseView& r);
  Reply retarget(const pb::ClientMessage& req, Clock::time_point began);
  // A structural edit (gmr/server/view.h's ViewEdit) of view `view_id`:
  // computed at once on a short motion, else on the server's edit thread
  // while this connection's requests wait unread (the reply then comes from
  // there; dispatch gives none). `decorate` adds what the edit reports.
  Reply edit_view(const pb::ClientMessage& req, Clock::time_point began, std::uint32_t view_id,
                  const std::function<Result<ViewEdit>(const View&)>& make, Views::EditDecoration decorate = nullptr);
  // A frame of a publication; the one that completes a marker calibration
  // is answered once the calibration, computed on the edit thread, is back.
  Reply publish_frame(const pb::ClientMessage& req, Clock::time_point began);
  // `work` (a Result<T>) on the server's edit thread while this connection's
  // requests are not read (they keep their order, and wait in the kernel;
  // everyone's frames go on), then `finish(*this, outcome)` on the control
  // loop gives the reply to `req` (dispatch gives none).
  template <class T, class Work, class Finish>
  void defer(const pb::ClientMessage& req, Clock::time_point began, std::string_view doing, Work work, Finish finish) {
    edit_deferred_ = true;
    if (auto c = link_.connection()) c->hold_reading(true);
    run_off_loop<T>(link_.services.edit_pool, link_.services.io, doing, std::move(work),
                    [self = weak_from_this(), finish = std::move(finish), request_id = req.request_id(),
                     kind = request_kind(req), began](Result<T> outcome) mutable {
                      auto handler = self.lock();
                      if (!handler || handler->stopped_) return;
                      Reply reply = finish(*handler, std::move(outcome));
                      handler->answer(request_id, kind, began, std::move(reply));
                      if (auto c = handler->link_.connection()) c->hold_reading(false);
                    });
  }
  // Requests only a 'control' connection may make (docs/security.md).
  static bool needs_control(pb::ClientMessage::BodyCase request);
  // The request's kind for metrics: its ClientMessage field's name.
  static std::string_view request_kind(const pb::ClientMessage& m);

  SessionLink link_;
  wire::UdpToken token_{};
  std::shared_ptr<UdpPublisher::Registration> udp_;
  Views views_{link_};
  Subscriptions subscriptions_{link_, views_, udp_};
  Publications publications_{link_};
  bool handshaked_ = false;
  Role role_ = Role::kNone;  // set by Hello
  bool stopped_ = false;
  bool edit_deferred_ = false;  // the request being dispatched is answered from the edit thread
  LogLimiter log_limit_;        // lines this client's bad requests may put in the log
};

}  // namespace gmr::server
