#include "requests/request_handler.h"

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <exception>
#include <new>
#include <utility>

#include "gmr/view/engine_pose.h"
#include "gmr/view/viewpoint.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/framing.h"
#include "streams/targets.h"

namespace gmr::server {

static_assert(static_cast<int>(pb::CONVENTION_PRESET_CUSTOM) == static_cast<int>(ConventionPreset::kCustom) &&
              static_cast<int>(pb::CONVENTION_PRESET_GODOT) == static_cast<int>(ConventionPreset::kGodot));

Result<OutputBasis> output_basis_of(const pb::Conventions& c, double motion_metres_per_unit) {
  // proto3 keeps enum values it does not know: refuse them rather than guess.
  if (!pb::ConventionPreset_IsValid(c.preset())) {
    return make_error("unknown conventions preset " + std::to_string(c.preset()));
  }
  Conventions g;
  g.preset = static_cast<ConventionPreset>(c.preset());
  g.up = c.up();
  g.forward = c.forward();
  g.left_handed = c.left_handed();
  g.target_metres_per_unit = c.target_metres_per_unit() == 0.0 ? 1.0 : c.target_metres_per_unit();
  // The request's word on the motion's unit, else the library's.
  g.source_metres_per_unit = c.source_metres_per_unit() != 0.0 ? c.source_metres_per_unit() : motion_metres_per_unit;
  return output_basis(g);
}


RequestHandler::RequestHandler(Services& services, const std::shared_ptr<Outbox>& outbox)
    : services_(services),
      connection_(outbox),
      connection_id_(outbox->id()),
      udp_(std::make_shared<UdpPublisher::Registration>()) {
  udp_->lane = outbox->lane();  // its UDP frames leave from its connection's I/O thread
}

void RequestHandler::start() {
  token_ = services_.udp.add_session([weak = weak_from_this()](const udp::endpoint& ep) {
    if (auto self = weak.lock()) self->udp_registered(ep);
  });
}

void RequestHandler::on_stop() {
  stopped_ = true;
  if (log_limit_.pending() > 0) {
    spdlog::warn("conn {}: {} more lines about its requests were suppressed", connection_id_, log_limit_.pending());
  }
  for (auto& [id, sub] : subs_) {
    sub.stream->remove(sub.target.get());
    services_.admission.release_rate(sub.rate_mhz);
  }
  subs_.clear();
  for (const auto& [id, v] : views_) forget_view(*v);
  views_.clear();
  while (!publications_.empty()) end_publication(publications_.begin()->first, "the live source disconnected");
  services_.udp.remove_session(token_);
}

void RequestHandler::send(const pb::ServerMessage& m) {
  auto c = connection_.lock();
  if (!c || c->stopped()) return;
  auto bytes = wire::frame_message(m, services_.cfg.max_message_bytes);
  if (!bytes.ok()) {
    bytes = wire::frame_message(
        error_message(m.request_id(), pb::ERROR_CODE_INTERNAL, "reply too large: " + bytes.error().message));
  }
  c->send(std::move(bytes).value());
}

std::string_view RequestHandler::request_kind(const pb::ClientMessage& m) {
  const auto* field = pb::ClientMessage::descriptor()->FindFieldByNumber(static_cast<int>(m.body_case()));
  return field != nullptr ? std::string_view(field->name()) : std::string_view("unknown");
}

void RequestHandler::on_message(const std::string& body) {
  pb::ClientMessage req;
  if (!req.ParseFromString(body)) {
    if (std::uint64_t suppressed = 0; log_limit_.allow(suppressed)) {
      spdlog::warn("conn {}: a {}-byte message is not a ClientMessage{}", connection_id_, body.size(),
                   suppressed ? " (" + std::to_string(suppressed) + " more such lines suppressed)" : std::string());
    }
    services_.observer.unparsable_request();
    send(error_message(0, pb::ERROR_CODE_BAD_REQUEST, "cannot parse the message as a gmr.stream.v1.ClientMessage"));
    return;
  }
  if (req.body_case() == pb::ClientMessage::kHeartbeat) return;  // the connection counted it as a read
  const Clock::time_point began = Clock::now();
  Reply reply;
  try {
    reply = dispatch(req, began);
  } catch (const std::bad_alloc&) {
    // The budgets (docs/protocol.md) make this rare; the server goes on.
    spdlog::error("conn {}: out of memory answering request {}", connection_id_, req.request_id());
    reply = Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "the server ran out of memory answering this request"};
  }
  // A view edit computed off the I/O thread answers when it is done.
  if (std::exchange(edit_deferred_, false)) return;
  answer(req.request_id(), request_kind(req), began, std::move(reply));
}

void RequestHandler::answer(std::uint64_t request_id, std::string_view kind, Clock::time_point began, Reply reply) {
  if (auto* refused = std::get_if<Refusal>(&reply)) {
    if (std::uint64_t suppressed = 0; spdlog::should_log(spdlog::level::debug) && log_limit_.allow(suppressed)) {
      spdlog::debug("conn {}: request {} refused: {}{}", connection_id_, request_id,
                    printable(refused->message, 200),
                    suppressed ? " (" + std::to_string(suppressed) + " more lines suppressed)" : std::string());
    }
    services_.observer.request(kind, Clock::now() - began, refused->code);
    send(error_message(request_id, refused->code, std::move(refused->message)));
    return;
  }
  auto& m = std::get<pb::ServerMessage>(reply);
  // A request that is answered only when refused (PublishFrame) gives an empty message.
  if (m.body_case() != pb::ServerMessage::BODY_NOT_SET) {
    m.set_request_id(request_id);
    send(m);
  }
  services_.observer.request(kind, Clock::now() - began, pb::ERROR_CODE_UNSPECIFIED);
}

std::pair<std::size_t, std::size_t> RequestHandler::subscription_count() const {
  std::size_t udp = 0;
  for (const auto& [id, s] : subs_) udp += dynamic_cast<const UdpTarget*>(s.target.get()) != nullptr ? 1 : 0;
  return {subs_.size() - udp, udp};
}

Reply RequestHandler::dispatch(const pb::ClientMessage& req, Clock::time_point began) {
  using C = pb::ClientMessage;
  if (req.body_case() == C::kHello) return hello(req.hello());
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
    case C::kListMotions: return list_motions();
    case C::kGetSkeleton: return get_skeleton(req.get_skeleton());
    case C::kCreateView: return create_view(req.create_view());
    case C::kCloseView: return close_view(req.close_view());
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
      return edit_view(req, began, r.view_id(), [&r](const View& v) { return v.edit_join(r.root()); },
                       [](const EditReport& e, pb::ViewInfo& info) { info.set_join_offset_spread(e.offset_spread); });
    }
    case C::kSetRoots: {
      const std::vector<std::string> roots(req.set_roots().roots().begin(), req.set_roots().roots().end());
      if (roots.empty()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "set roots: give at least one root"};
      return edit_view(req, began, req.set_roots().view_id(), [&roots](const View& v) { return v.edit_set_roots(roots); });
    }
    case C::kStripDummies:
      return edit_view(req, began, req.strip_dummies().view_id(), [](const View& v) { return v.edit_strip_dummies(); },
                       [](const EditReport& e, pb::ViewInfo& info) {
                         for (const auto& name : e.removed) info.add_removed(name);
                       });
    case C::kSetCoordinates: return set_coordinates(req.set_coordinates());
    case C::kQueryFrames: return query(req.query_frames());
    case C::kSubscribe: return subscribe(req.subscribe());
    case C::kUnsubscribe: return unsubscribe(req.unsubscribe());
    case C::kPause: return pause(req.pause());
    case C::kResume: return resume(req.resume());
    case C::kSeek: return seek(req.seek());
    case C::kGetStats: return stats();
    case C::kPublish: return publish(req.publish());
    case C::kPublishFrame: return publish_frame(req.publish_frame());
    case C::kUnpublish: return unpublish(req.unpublish());
    default: return Refusal{pb::ERROR_CODE_UNKNOWN_REQUEST, "unknown request"};
  }
}

bool RequestHandler::needs_control(pb::ClientMessage::BodyCase request) {
  using C = pb::ClientMessage;
  switch (request) {
    case C::kShiftRoot:
    case C::kSplit:
    case C::kJoin:
    case C::kSetRoots:
    case C::kStripDummies:
    case C::kGetStats: return true;
    default: return false;
  }
}

Reply RequestHandler::hello(const pb::Hello& h) {
  if (h.protocol_version() != wire::kProtocolVersion) {
    spdlog::warn("conn {}: refused protocol version {} (this server speaks {})", connection_id_, h.protocol_version(),
                 wire::kProtocolVersion);
    if (auto c = connection_.lock()) c->close_after_reply();
    return Refusal{pb::ERROR_CODE_VERSION_MISMATCH, "client speaks protocol version " +
                                                        std::to_string(h.protocol_version()) +
                                                        ", this server speaks version " +
                                                        std::to_string(wire::kProtocolVersion)};
  }
  const ServerConfig& cfg = services_.cfg;
  // The role: the token's, or the anonymous one. A token the server does not
  // know is refused rather than taken as anonymous (a typo should show); a
  // server without tokens takes every client as anonymous.
  Role role = cfg.anonymous;
  if (cfg.credentials && !h.auth_token().empty()) role = cfg.credentials->role_of(h.auth_token());
  if (role == Role::kNone) {
    const bool had_token = !h.auth_token().empty();
    if (std::uint64_t suppressed = 0; services_.admission.hello_refused(suppressed)) {
      spdlog::warn("conn {}: refused at Hello: {}{}", connection_id_,
                   had_token ? "unknown token" : "no token and anonymous clients may not connect",
                   suppressed ? " (" + std::to_string(suppressed) + " more such lines suppressed)" : std::string());
    }
    if (auto c = connection_.lock()) c->close_after_reply();
    return Refusal{pb::ERROR_CODE_UNAUTHENTICATED, had_token ? "the server does not know this token"
                                                             : "this server needs a token (ClientOptions::auth_token, "
                                                               "gmr --token or GMR_TOKEN)"};
  }
  role_ = role;
  handshaked_ = true;
  if (auto c = connection_.lock()) c->established();
  services_.admission.established(connection_id_);
  spdlog::info("conn {}: hello from {} ({})", connection_id_, printable(h.client_name()), role_name(role_));
  pb::ServerMessage out;
  auto* r = out.mutable_hello();
  r->set_protocol_version(wire::kProtocolVersion);
  r->set_server_name(cfg.server_name);
  r->set_udp_token(std::string(reinterpret_cast<const char*>(token_.data()), token_.size()));
  r->set_udp_port(services_.udp.port());
  r->set_max_message_bytes(cfg.max_message_bytes);
  r->set_heartbeat_interval_ms(static_cast<std::uint32_t>(cfg.heartbeat_interval.count()));
  r->set_idle_timeout_ms(static_cast<std::uint32_t>(cfg.idle_timeout.count()));
  r->set_role(role_ == Role::kPublish   ? pb::ROLE_PUBLISH
              : role_ == Role::kControl ? pb::ROLE_CONTROL
                                        : pb::ROLE_READ);
  r->set_server_time_ns(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
  return out;
}

Reply RequestHandler::stats() {
  auto c = connection_.lock();
  const ConnectionCounters own = c ? c->counters() : ConnectionCounters{};
  pb::ServerMessage out;
  auto* st = out.mutable_stats();
  st->set_connections(static_cast<std::uint32_t>(services_.admission.connections().size()));
  st->set_streams(static_cast<std::uint32_t>(services_.streams.live()));
  st->set_frames_computed(services_.counters.frames_computed);
  st->set_frames_computed_float(services_.counters.frames_computed_float);
  st->set_frames_encoded(services_.counters.frames_encoded);
  st->set_frames_sent(own.frames_sent);
  st->set_frames_dropped(own.frames_dropped);
  // Every connection's, in one snapshot: what a load test measures its
  // window with (2 requests, not 2 per client).
  const ConnectionCounters all = services_.admission.totals();
  st->set_frames_sent_total(all.frames_sent);
  st->set_frames_dropped_total(all.frames_dropped);
  st->set_frames_skipped(own.frames_skipped);
  st->set_frames_skipped_total(services_.counters.frames_skipped);
  st->set_queued_bytes(own.queued_bytes);
  st->set_max_queued_bytes(own.max_queued_bytes);
  st->set_committed_frames_per_second(services_.admission.committed_frames_per_second());
  st->set_send_budget(services_.cfg.send_budget);
  st->set_subscriptions_refused(services_.admission.subscriptions_refused());
  st->set_live_sources(static_cast<std::uint32_t>(services_.catalog.live_sources().size()));
  st->set_live_frames_received(services_.catalog.live_frames_received());
  st->set_live_frames_refused(services_.catalog.live_frames_refused());
  st->set_multicast_frames_sent(services_.multicast.frames_sent);
  st->set_io_threads(static_cast<std::uint32_t>(services_.lanes ? services_.lanes->size() : 1));
  if (auto conn = connection_.lock()) st->set_io_thread(static_cast<std::uint32_t>(conn->lane()));
  return out;
}

}  // namespace gmr::server
