#include "requests/request_handler.h"

#include <spdlog/spdlog.h>

#include <exception>
#include <map>
#include <memory>
#include <new>
#include <utility>
#include <variant>

#include "gmr/wire/framing.h"
#include "requests/rig.h"
#include "transport/connection_log.h"

namespace gmr::server {

RequestHandler::RequestHandler(Services& services, const std::shared_ptr<Outbox>& outbox)
    : link_(services, outbox), udp_(std::make_shared<UdpPublisher::Registration>()) {
  udp_->lane = outbox->lane();  // its UDP frames leave from its connection's I/O thread
  views_.on_changed([this](const View& v) { subscriptions_.view_changed(v); });
}

void RequestHandler::start() {
  // The subscriptions' targets report to them for as long as this session lives.
  subscriptions_.set_self(std::shared_ptr<SubscriptionEvents>(shared_from_this(), &subscriptions_));
  token_ = link_.services.udp.add_session([weak = weak_from_this()](const udp::endpoint& ep) {
    if (auto self = weak.lock()) self->udp_registered(ep);
  });
}

void RequestHandler::on_stop() {
  stopped_ = true;
  if (log_limit_.pending() > 0) {
    spdlog::warn("conn {}: {} more lines about its requests were suppressed", link_.connection_id,
                 log_limit_.pending());
  }
  subscriptions_.clear();
  views_.clear();
  publications_.end_all("the live source disconnected");
  link_.services.udp.remove_session(token_);
}

std::string_view RequestHandler::request_kind(const pb::ClientMessage& m) {
  const auto* field = pb::ClientMessage::descriptor()->FindFieldByNumber(static_cast<int>(m.body_case()));
  return field != nullptr ? std::string_view(field->name()) : std::string_view("unknown");
}

void RequestHandler::on_message(const std::string& body) {
  pb::ClientMessage req;
  if (!req.ParseFromString(body)) {
    if (std::uint64_t suppressed = 0; log_limit_.allow(suppressed)) {
      spdlog::warn("conn {}: a {}-byte message is not a ClientMessage{}", link_.connection_id, body.size(),
                   suppressed ? " (" + std::to_string(suppressed) + " more such lines suppressed)" : std::string());
    }
    link_.services.observer.unparsable_request();
    link_.send(
        error_message(0, pb::ERROR_CODE_BAD_REQUEST, "cannot parse the message as a gmr.stream.v1.ClientMessage"));
    return;
  }
  if (req.body_case() == pb::ClientMessage::kHeartbeat) return;  // the connection counted it as a read
  const Clock::time_point began = Clock::now();
  Reply reply;
  try {
    reply = dispatch(req, began);
  } catch (const std::bad_alloc&) {
    // The budgets (docs/protocol.md) make this rare; the server goes on.
    spdlog::error("conn {}: out of memory answering request {}", link_.connection_id, req.request_id());
    reply = Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "the server ran out of memory answering this request"};
  }
  // Views and sources come and go only by requests (and the connection's end).
  if (auto c = link_.connection()) c->set_holding(views_.count() > 0 || publications_.count() > 0);
  // A view edit computed off the I/O thread answers when it is done.
  if (std::exchange(edit_deferred_, false)) return;
  answer(req.request_id(), request_kind(req), began, std::move(reply));
}

void RequestHandler::answer(std::uint64_t request_id, std::string_view kind, Clock::time_point began, Reply reply) {
  if (auto* refused = std::get_if<Refusal>(&reply)) {
    if (std::uint64_t suppressed = 0; spdlog::should_log(spdlog::level::debug) && log_limit_.allow(suppressed)) {
      spdlog::debug("conn {}: request {} refused: {}{}", link_.connection_id, request_id,
                    printable(refused->message, 200),
                    suppressed ? " (" + std::to_string(suppressed) + " more lines suppressed)" : std::string());
    }
    link_.services.observer.request(kind, Clock::now() - began, refused->code);
    link_.send(error_message(request_id, refused->code, std::move(refused->message)));
    return;
  }
  auto& m = std::get<pb::ServerMessage>(reply);
  // A request that is answered only when refused (PublishFrame) gives an empty message.
  if (m.body_case() != pb::ServerMessage::BODY_NOT_SET) {
    m.set_request_id(request_id);
    link_.send(m);
  }
  link_.services.observer.request(kind, Clock::now() - began, pb::ERROR_CODE_UNSPECIFIED);
}

Reply RequestHandler::dispatch(const pb::ClientMessage& req, Clock::time_point began) {
  using C = pb::ClientMessage;
  if (req.body_case() == C::kHello) {
    // The role is settled once: a second Hello would re-evaluate it under
    // what the first one opened (a publication, subscriptions).
    if (handshaked_) {
      return Refusal{pb::ERROR_CODE_BAD_REQUEST, "Hello was already said on this connection (as '" +
                                                     std::string(role_name(role_)) +
                                                     "'): connect again for another role"};
    }
    return hello(req.hello());
  }
  if (req.body_case() == C::BODY_NOT_SET) {
    return Refusal{pb::ERROR_CODE_UNKNOWN_REQUEST, "unknown or empty request (this server speaks protocol version " +
                                                       std::to_string(wire::kProtocolVersion) + ")"};
  }
  if (!handshaked_) return Refusal{pb::ERROR_CODE_HANDSHAKE_REQUIRED, "send Hello first"};
  if (role_ < Role::kControl && needs_control(req.body_case())) {
    return Refusal{pb::ERROR_CODE_PERMISSION_DENIED,
                   "this connection's role is '" + std::string(role_name(role_)) +
                       "': structural view edits and statistics need a 'control' token (docs/security.md)"};
  }
  switch (req.body_case()) {
    case C::kListMotions:
      return views_.list_motions();
    case C::kGetSkeleton:
      return views_.get_skeleton(req.get_skeleton());
    case C::kCreateView:
      return views_.create(req.create_view());
    case C::kCloseView:
      return close_view(req.close_view());
    case C::kShiftRoot: {
      const auto& r = req.shift_root();
      return edit_view(req, began, r.view_id(), [&r](const View& v) { return v.edit_shift_root(r.joint()); });
    }
    case C::kSplit: {
      const auto& r = req.split();
      return edit_view(req, began, r.view_id(), [&r](const View& v) { return v.edit_split(r.joint()); });
    }
    case C::kJoin: {
      const auto& r = req.join();
      return edit_view(
          req, began, r.view_id(), [&r](const View& v) { return v.edit_join(r.root()); },
          [](const EditReport& e, pb::ViewInfo& info) { info.set_join_offset_spread(e.offset_spread); });
    }
    case C::kSetRoots: {
      const std::vector<std::string> roots(req.set_roots().roots().begin(), req.set_roots().roots().end());
      if (roots.empty()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "set roots: give at least one root"};
      return edit_view(req, began, req.set_roots().view_id(),
                       [&roots](const View& v) { return v.edit_set_roots(roots); });
    }
    case C::kStripDummies:
      return edit_view(
          req, began, req.strip_dummies().view_id(), [](const View& v) { return v.edit_strip_dummies(); },
          [](const EditReport& e, pb::ViewInfo& info) {
            for (const auto& name : e.removed) info.add_removed(name);
          });
    case C::kRetarget:
      return retarget(req, began);
    case C::kSetCoordinates:
      return views_.set_coordinates(req.set_coordinates());
    case C::kQueryFrames:
      return views_.query(req.query_frames());
    case C::kSubscribe:
      return subscriptions_.subscribe(req.subscribe());
    case C::kUnsubscribe:
      return subscriptions_.unsubscribe(req.unsubscribe());
    case C::kPause:
      return subscriptions_.pause(req.pause());
    case C::kResume:
      return subscriptions_.resume(req.resume());
    case C::kSeek:
      return subscriptions_.seek(req.seek());
    case C::kGetStats:
      return stats();
    case C::kPublish:
      return publications_.publish(req.publish(), role_);
    case C::kPublishFrame:
      return publish_frame(req, began);
    case C::kUnpublish:
      return publications_.unpublish(req.unpublish());
    default:
      return Refusal{pb::ERROR_CODE_UNKNOWN_REQUEST, "unknown request"};
  }
}

bool RequestHandler::needs_control(pb::ClientMessage::BodyCase request) {
  using C = pb::ClientMessage;
  switch (request) {
    case C::kRetarget:
    case C::kShiftRoot:
    case C::kSplit:
    case C::kJoin:
    case C::kSetRoots:
    case C::kStripDummies:
    case C::kGetStats:
      return true;
    default:
      return false;
  }
}

Reply RequestHandler::hello(const pb::Hello& h) {
  if (h.protocol_version() != wire::kProtocolVersion) {
    log_connection(spdlog::level::warn, "conn {}: refused protocol version {} (this server speaks {})",
                   link_.connection_id, h.protocol_version(), wire::kProtocolVersion);
    if (auto c = link_.connection()) c->close_after_reply();
    return Refusal{pb::ERROR_CODE_VERSION_MISMATCH,
                   "client speaks protocol version " + std::to_string(h.protocol_version()) +
                       ", this server speaks version " + std::to_string(wire::kProtocolVersion)};
  }
  const ServerConfig& cfg = link_.services.cfg;
  Admission& admission = link_.services.admission;
  const auto* entry = admission.find(link_.connection_id);
  const std::string address = entry != nullptr ? entry->address : std::string();
  // An address that keeps offering tokens the server does not know waits
  // before its next one is even looked at.
  if (const auto wait = admission.auth_wait(address)) {
    std::uint64_t suppressed = 0;
    admission.hello_refused(suppressed);
    if (auto c = link_.connection()) c->close_after_reply();
    const auto ms = std::chrono::ceil<std::chrono::milliseconds>(*wait).count();
    return Refusal{pb::ERROR_CODE_UNAUTHENTICATED,
                   "too many refused Hellos from this address: try again in " + std::to_string(ms) + " ms"};
  }
  // The role: the token's, or the anonymous one. A token the server does not
  // know is refused rather than taken as anonymous (a typo should show); a
  // server without tokens takes every client as anonymous.
  Role role = cfg.anonymous;
  if (cfg.credentials && !h.auth_token().empty()) role = cfg.credentials->role_of(h.auth_token());
  if (role == Role::kNone) {
    const bool had_token = !h.auth_token().empty();
    admission.auth_failed(address);
    if (std::uint64_t suppressed = 0; admission.hello_refused(suppressed)) {
      spdlog::warn("conn {}: refused at Hello: {}{}", link_.connection_id,
                   had_token ? "unknown token" : "no token and anonymous clients may not connect",
                   suppressed ? " (" + std::to_string(suppressed) + " more such lines suppressed)" : std::string());
    }
    if (auto c = link_.connection()) c->close_after_reply();
    return Refusal{pb::ERROR_CODE_UNAUTHENTICATED, had_token ? "the server does not know this token"
                                                             : "this server needs a token (ClientOptions::auth_token, "
                                                               "gmr --token or GMR_TOKEN)"};
  }
  // With tokens, clients without one share a bounded part of the slots.
  if (cfg.credentials && h.auth_token().empty()) {
    if (std::string why = admission.admit_anonymous(link_.connection_id); !why.empty()) {
      if (auto c = link_.connection()) c->close_after_reply();
      return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, why};
    }
  }
  admission.auth_succeeded(address);
  role_ = role;
  handshaked_ = true;
  if (auto c = link_.connection()) c->established();
  link_.services.admission.established(link_.connection_id);
  log_connection(spdlog::level::info, "conn {}: hello from {} ({})", link_.connection_id, printable(h.client_name()),
                 role_name(role_));
  pb::ServerMessage out;
  auto* r = out.mutable_hello();
  r->set_protocol_version(wire::kProtocolVersion);
  r->set_server_name(cfg.server_name);
  r->set_udp_token(std::string(reinterpret_cast<const char*>(token_.data()), token_.size()));
  r->set_udp_port(link_.services.udp.port());
  r->set_max_message_bytes(cfg.max_message_bytes);
  r->set_heartbeat_interval_ms(static_cast<std::uint32_t>(cfg.heartbeat_interval.count()));
  r->set_idle_timeout_ms(static_cast<std::uint32_t>(cfg.idle_timeout.count()));
  r->set_role(role_ == Role::kPublish ? pb::ROLE_PUBLISH : role_ == Role::kControl ? pb::ROLE_CONTROL : pb::ROLE_READ);
  r->set_server_time_ns(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
  return out;
}

Reply RequestHandler::stats() {
  auto c = link_.connection();
  const ConnectionCounters own = c ? c->counters() : ConnectionCounters{};
  pb::ServerMessage out;
  auto* st = out.mutable_stats();
  st->set_connections(static_cast<std::uint32_t>(link_.services.admission.connections().size()));
  st->set_streams(static_cast<std::uint32_t>(link_.services.streams.live()));
  st->set_frames_computed(link_.services.counters.frames_computed);
  st->set_frames_computed_float(link_.services.counters.frames_computed_float);
  st->set_frames_encoded(link_.services.counters.frames_encoded);
  st->set_frames_sent(own.frames_sent);
  st->set_frames_dropped(own.frames_dropped);
  // Every connection's, in one snapshot: what a load test measures its
  // window with (2 requests, not 2 per client).
  const ConnectionCounters all = link_.services.admission.totals();
  st->set_frames_sent_total(all.frames_sent);
  st->set_frames_dropped_total(all.frames_dropped);
  st->set_frames_skipped(own.frames_skipped);
  st->set_frames_skipped_total(link_.services.counters.frames_skipped);
  st->set_queued_bytes(own.queued_bytes);
  st->set_max_queued_bytes(own.max_queued_bytes);
  st->set_committed_frames_per_second(link_.services.admission.committed_frames_per_second());
  st->set_send_budget(link_.services.cfg.send_budget);
  st->set_subscriptions_refused(link_.services.admission.subscriptions_refused());
  st->set_live_sources(static_cast<std::uint32_t>(link_.services.catalog.live_sources().size()));
  st->set_live_frames_received(link_.services.catalog.live_frames_received());
  st->set_live_frames_refused(link_.services.catalog.live_frames_refused());
  st->set_live_frames_over_rate(link_.services.catalog.live_frames_over_rate());
  st->set_live_edit_replays(link_.services.catalog.live_edit_replays());
  const MarkerFrameCounts& markers = link_.services.catalog.live_markers();
  st->set_live_marker_points_missing(markers.missing);
  st->set_live_marker_parts_held(markers.held);
  st->set_live_marker_points_outliers(markers.outliers);
  st->set_live_marker_frames_unsolved(markers.refused);
  st->set_multicast_frames_sent(link_.services.multicast.frames_sent);
  st->set_io_threads(static_cast<std::uint32_t>(link_.services.lanes ? link_.services.lanes->size() : 1));
  if (auto conn = link_.connection()) st->set_io_thread(static_cast<std::uint32_t>(conn->lane()));
  return out;
}

Reply RequestHandler::retarget(const pb::ClientMessage& req, Clock::time_point began) {
  const pb::Retarget& r = req.retarget();
  auto rig = check_rig(r, link_.services.cfg);
  if (auto* refusal = std::get_if<Refusal>(&rig)) return *refusal;
  std::map<std::string, std::string> target_map(r.target_map().begin(), r.target_map().end());
  std::map<std::string, std::string> source_map(r.source_map().begin(), r.source_map().end());
  return edit_view(req, began, r.view_id(), [&](const View& v) {
    return v.edit_retarget(std::get<std::shared_ptr<const Motion>>(std::move(rig)), std::move(target_map),
                           std::move(source_map), r.target().metres_per_unit());
  });
}

Reply RequestHandler::close_view(const pb::CloseView& r) {
  if (!views_.find(r.view_id())) return unknown_view(r.view_id());
  subscriptions_.drop_view(r.view_id());
  views_.close(r.view_id());
  return ack();
}

Reply RequestHandler::edit_view(const pb::ClientMessage& req, Clock::time_point began, std::uint32_t view_id,
                                const std::function<Result<ViewEdit>(const View&)>& make,
                                Views::EditDecoration decorate) {
  View* v = views_.find(view_id);
  if (!v) return unknown_view(view_id);
  auto edit = make(*v);
  if (!edit.ok()) return refusal_of(edit.error());
  // What the edit may write, before any of it is computed: past a view
  // limit it is refused here (before, a channel-less 2^20-frame BVH and one
  // SetRoots took 4.29 GB and 10 s before the limit was checked on the copy).
  const ServerConfig& cfg = link_.services.cfg;
  const std::uint64_t bound = edit->values_bound();
  const std::uint64_t bound_bytes = bound * sizeof(double);
  const std::uint64_t limit = std::min<std::uint64_t>(cfg.max_view_bytes_per_connection, cfg.max_view_bytes);
  if (bound_bytes > limit) {
    const Motion& m = *edit->base()->motion;
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "the edit could write up to " + std::to_string(bound_bytes) + " bytes (" +
                       std::to_string(m.frame_count) + " frames x " +
                       std::to_string(bound / std::max<std::uint64_t>(1, m.frame_count)) +
                       " channels), above the view limit of " + std::to_string(limit) +
                       " bytes (--max-view-bytes-per-connection, --max-view-bytes)"};
  }
  // A short motion's edit costs less than a trip to the edit thread; what it
  // may write counts, not only what it reads.
  if (std::max<std::uint64_t>(edit->values(), bound) <= cfg.edit_inline_values) {
    return views_.commit_edit(view_id, *edit, edit->run(), decorate);
  }
  // A long one is computed on the edit thread. The edit goes with the
  // answer, so it is let go on the control loop, as the view it holds.
  auto owned = std::make_unique<const ViewEdit>(std::move(edit).value());
  const ViewEdit* running = owned.get();
  defer<std::shared_ptr<const ViewContent>>(
      req, began, "the edit", [running] { return running->run(); },
      [owned = std::move(owned), view_id, decorate](RequestHandler& handler,
                                                    Result<std::shared_ptr<const ViewContent>> next) {
        return handler.views_.commit_edit(view_id, *owned, std::move(next), decorate);
      });
  return pb::ServerMessage{};
}

Reply RequestHandler::publish_frame(const pb::ClientMessage& req, Clock::time_point began) {
  Reply reply = publications_.publish_frame(req.publish_frame());
  auto due = publications_.take_due_calibration();
  if (!due) return reply;
  defer<MarkerFrameSolver>(
      req, began, "the marker calibration", [calibration = std::move(due->calibration)] { return calibration.run(); },
      [id = due->publication](RequestHandler& handler, Result<MarkerFrameSolver> solver) {
        return handler.publications_.calibrated(id, std::move(solver));
      });
  return reply;
}

void RequestHandler::udp_registered(const udp::endpoint& ep) {
  if (stopped_) return;
  const bool first = !udp_->endpoint || *udp_->endpoint != ep;
  udp_->endpoint = ep;
  if (first) {
    log_connection(spdlog::level::info, "conn {}: UDP endpoint {}:{} registered", link_.connection_id,
                   ep.address().to_string(), ep.port());
  }
  pb::ServerMessage m;
  m.mutable_udp_registered()->set_endpoint(ep.address().to_string() + ":" + std::to_string(ep.port()));
  link_.send(m);
}

}  // namespace gmr::server
