#include "request_handler.h"

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <exception>
#include <new>
#include <utility>

#include "gmr/view/engine_pose.h"
#include "gmr/view/viewpoint.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/framing.h"
#include "targets.h"

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


RequestHandler::RequestHandler(Server::Impl& server, const std::shared_ptr<Outbox>& outbox)
    : server_(server),
      connection_(outbox),
      connection_id_(outbox->id()),
      udp_(std::make_shared<UdpPublisher::Registration>()) {
  udp_->lane = outbox->lane();  // its UDP frames leave from its connection's I/O thread
}

void RequestHandler::start() {
  token_ = server_.udp.add_session([weak = weak_from_this()](const udp::endpoint& ep) {
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
    server_.committed_mhz -= sub.rate_mhz;
  }
  subs_.clear();
  for (const auto& [id, v] : views_) forget_view(*v);
  views_.clear();
  while (!publications_.empty()) end_publication(publications_.begin()->first, "the live source disconnected");
  server_.udp.remove_session(token_);
}

void RequestHandler::send(const pb::ServerMessage& m) {
  auto c = connection_.lock();
  if (!c || c->stopped()) return;
  auto bytes = wire::frame_message(m, server_.cfg.max_message_bytes);
  if (!bytes.ok()) {
    bytes = wire::frame_message(
        error_message(m.request_id(), pb::ERROR_CODE_INTERNAL, "reply too large: " + bytes.error().message));
  }
  c->send(std::move(bytes).value());
}

namespace {
// The request's kind for metrics: its ClientMessage field's name.
std::string_view request_kind(const pb::ClientMessage& m) {
  const auto* field = pb::ClientMessage::descriptor()->FindFieldByNumber(static_cast<int>(m.body_case()));
  return field != nullptr ? std::string_view(field->name()) : std::string_view("unknown");
}
}  // namespace

void RequestHandler::on_message(const std::string& body) {
  pb::ClientMessage req;
  if (!req.ParseFromString(body)) {
    if (std::uint64_t suppressed = 0; log_limit_.allow(suppressed)) {
      spdlog::warn("conn {}: a {}-byte message is not a ClientMessage{}", connection_id_, body.size(),
                   suppressed ? " (" + std::to_string(suppressed) + " more such lines suppressed)" : std::string());
    }
    server_.metrics.unparsable_request();
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
    server_.metrics.request(kind, Clock::now() - began, refused->code);
    send(error_message(request_id, refused->code, std::move(refused->message)));
    return;
  }
  auto& m = std::get<pb::ServerMessage>(reply);
  // A request that is answered only when refused (PublishFrame) gives an empty message.
  if (m.body_case() != pb::ServerMessage::BODY_NOT_SET) {
    m.set_request_id(request_id);
    send(m);
  }
  server_.metrics.request(kind, Clock::now() - began, pb::ERROR_CODE_UNSPECIFIED);
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
  const ServerConfig& cfg = server_.cfg;
  // The role: the token's, or the anonymous one. A token the server does not
  // know is refused rather than taken as anonymous (a typo should show); a
  // server without tokens takes every client as anonymous.
  Role role = cfg.anonymous;
  if (cfg.credentials && !h.auth_token().empty()) role = cfg.credentials->role_of(h.auth_token());
  if (role == Role::kNone) {
    const bool had_token = !h.auth_token().empty();
    if (std::uint64_t suppressed = 0; server_.auth_log.allow(suppressed)) {
      spdlog::warn("conn {}: refused at Hello: {}{}", connection_id_,
                   had_token ? "unknown token" : "no token and anonymous clients may not connect",
                   suppressed ? " (" + std::to_string(suppressed) + " more such lines suppressed)" : std::string());
    }
    ++server_.auth_refused;
    if (auto c = connection_.lock()) c->close_after_reply();
    return Refusal{pb::ERROR_CODE_UNAUTHENTICATED, had_token ? "the server does not know this token"
                                                             : "this server needs a token (ClientOptions::auth_token, "
                                                               "gmr --token or GMR_TOKEN)"};
  }
  role_ = role;
  handshaked_ = true;
  if (auto c = connection_.lock()) c->established();
  server_.pending_hello.erase(connection_id_);
  spdlog::info("conn {}: hello from {} ({})", connection_id_, printable(h.client_name()), role_name(role_));
  pb::ServerMessage out;
  auto* r = out.mutable_hello();
  r->set_protocol_version(wire::kProtocolVersion);
  r->set_server_name(cfg.server_name);
  r->set_udp_token(std::string(reinterpret_cast<const char*>(token_.data()), token_.size()));
  r->set_udp_port(server_.udp.port());
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

Reply RequestHandler::list_motions() const {
  pb::ServerMessage out;
  auto* list = out.mutable_motions();
  for (const auto& e : server_.library) {
    auto* m = list->add_motions();
    m->set_name(e.name);
    m->set_joint_count(static_cast<std::uint32_t>(e.motion->skeleton.size()));
    m->set_frame_count(e.motion->frame_count);
    m->set_frame_time(e.motion->frame_time);
    m->set_source(e.source);
    m->set_metres_per_unit(e.metres_per_unit);
  }
  for (const auto& [name, source] : server_.live) {
    auto* m = list->add_motions();
    m->set_name(name);
    m->set_joint_count(static_cast<std::uint32_t>(source->latest()->skeleton.size()));
    m->set_frame_count(source->frames());
    m->set_frame_time(source->frame_time());
    m->set_source("live");
    m->set_metres_per_unit(source->metres_per_unit());
    m->set_live(true);
  }
  return out;
}

Reply RequestHandler::get_skeleton(const pb::GetSkeleton& r) const {
  if (auto source = find_live(r.motion())) {
    const auto basis = output_basis_of(r.conventions(), source->metres_per_unit());
    if (!basis.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, basis.error().message};
    pb::ServerMessage out;
    out.mutable_skeleton()->set_motion(source->name());
    wire::to_proto(*source->latest(), *basis, *out.mutable_skeleton()->mutable_skeleton());
    return out;
  }
  auto it = server_.by_name.find(r.motion());
  if (it == server_.by_name.end()) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown motion '" + r.motion() + "'"};
  const LibraryEntry& e = server_.library[it->second];
  const auto basis = output_basis_of(r.conventions(), e.metres_per_unit);
  if (!basis.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, basis.error().message};
  pb::ServerMessage out;
  out.mutable_skeleton()->set_motion(it->first);
  wire::to_proto(*e.motion, *basis, *out.mutable_skeleton()->mutable_skeleton());
  return out;
}

Reply RequestHandler::create_view(const pb::CreateView& r) {
  auto it = server_.by_name.find(r.motion());
  auto source = it == server_.by_name.end() ? find_live(r.motion()) : nullptr;
  if (it == server_.by_name.end() && !source) {
    return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown motion '" + r.motion() + "'"};
  }
  if (views_.size() >= server_.cfg.max_views_per_connection) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "at most " + std::to_string(server_.cfg.max_views_per_connection) + " views per connection"};
  }
  const std::uint32_t id = next_view_++;
  auto v = source ? std::make_unique<View>(id, source)
                  : std::make_unique<View>(id, it->first, server_.library[it->second].motion,
                                           server_.compiled_form(it->second));
  pb::ServerMessage out;
  *out.mutable_view() = view_info(*v);
  views_.emplace(id, std::move(v));
  return out;
}

Reply RequestHandler::close_view(const pb::CloseView& r) {
  View* v = find_view(r.view_id());
  if (!v) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown view " + std::to_string(r.view_id())};
  std::vector<std::uint32_t> ids;
  for (auto& [id, sub] : subs_) {
    if (sub.view_id == v->id()) ids.push_back(id);
  }
  for (auto id : ids) drop_subscription(id);
  forget_view(*v);
  views_.erase(v->id());
  pb::ServerMessage out;
  out.mutable_ack();
  return out;
}

namespace {

// A library error as the protocol's: NOT_FOUND for an unknown joint,
// RESOURCE_EXHAUSTED for memory, FAILED_PRECONDITION for anything else the
// view refuses (the view is left as it was).
Refusal refusal_of(const Error& e) {
  switch (e.kind) {
    case ErrorKind::kNotFound: return Refusal{pb::ERROR_CODE_NOT_FOUND, e.to_string()};
    case ErrorKind::kResourceExhausted: return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, e.to_string()};
    default: return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, e.to_string()};
  }
}

}  // namespace

Reply RequestHandler::edit_view(const pb::ClientMessage& req, Clock::time_point began, std::uint32_t view_id,
                                const std::function<Result<ViewEdit>(const View&)>& make, EditDecoration decorate) {
  View* v = find_view(view_id);
  if (!v) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown view " + std::to_string(view_id)};
  auto edit = make(*v);
  if (!edit.ok()) return refusal_of(edit.error());
  // A short motion's edit costs less than a trip to the edit thread.
  if (edit->values() <= server_.cfg.edit_inline_values) return commit_edit(view_id, *edit, edit->run(), decorate);
  // A long one is computed on the edit thread; meanwhile this connection's
  // requests are not read (they keep their order, and wait in the kernel),
  // and everyone's frames go on.
  edit_deferred_ = true;
  if (auto c = connection_.lock()) c->hold_reading(true);
  net::post(server_.edit_pool, [self = weak_from_this(), &io = server_.io, edit = std::move(edit).value(), view_id,
                                decorate, request_id = req.request_id(), kind = request_kind(req), began]() mutable {
    auto next = [&]() -> Result<std::shared_ptr<const ViewContent>> {
      try {
        return edit.run();
      } catch (const std::bad_alloc&) {
        return make_error(ErrorKind::kResourceExhausted, "the server ran out of memory computing the edit");
      } catch (const std::exception& e) {  // nothing may leave the edit thread's handler
        return make_error(ErrorKind::kFailedPrecondition, std::string("the edit failed: ") + e.what());
      }
    }();
    net::post(io, [self = std::move(self), edit = std::move(edit), next = std::move(next), view_id, decorate,
                   request_id, kind, began]() mutable {
      auto handler = self.lock();
      if (!handler) return;
      if (handler->stopped_) return;
      Reply reply = handler->commit_edit(view_id, edit, std::move(next), decorate);
      handler->answer(request_id, kind, began, std::move(reply));
      if (auto c = handler->connection_.lock()) c->hold_reading(false);
    });
  });
  return pb::ServerMessage{};
}

Reply RequestHandler::commit_edit(std::uint32_t view_id, const ViewEdit& edit,
                                  Result<std::shared_ptr<const ViewContent>> next, EditDecoration decorate) {
  View* v = find_view(view_id);
  if (!v) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown view " + std::to_string(view_id)};
  if (!next.ok()) return refusal_of(next.error());
  const auto before = v->content();
  const std::uint64_t old_bytes = owned_bytes(*v);
  if (Status s = v->commit(edit, std::move(next).value()); !s.ok()) return refusal_of(s.error());
  // The view budget: an edit whose copy would pass it is undone and refused.
  const std::uint64_t new_bytes = owned_bytes(*v);
  const ServerConfig& cfg = server_.cfg;
  const std::uint64_t mine = view_bytes_ - old_bytes + new_bytes;
  const std::uint64_t all = server_.view_bytes - old_bytes + new_bytes;
  if (new_bytes > old_bytes && (mine > cfg.max_view_bytes_per_connection || all > cfg.max_view_bytes)) {
    v->restore(before);
    const bool own = mine > cfg.max_view_bytes_per_connection;
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "the edited view would hold " + std::to_string(new_bytes) + " bytes of motion; views " +
                       (own ? "of this connection" : "of all connections") + " would then hold " +
                       std::to_string(own ? mine : all) + " bytes, above the server's limit of " +
                       std::to_string(own ? cfg.max_view_bytes_per_connection : cfg.max_view_bytes) +
                       ": close views you no longer use"};
  }
  view_bytes_ = mine;
  server_.view_bytes = all;
  view_changed(*v);
  pb::ServerMessage out;
  *out.mutable_view() = view_info(*v);
  if (decorate != nullptr) decorate(edit.report(), *out.mutable_view());
  return out;
}

Reply RequestHandler::set_coordinates(const pb::SetCoordinates& r) {
  View* v = find_view(r.view_id());
  if (!v) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown view " + std::to_string(r.view_id())};
  if (Status s = v->set_relative_to(r.relative_to()); !s.ok()) return refusal_of(s.error());
  view_changed(*v);  // the same motion: the same bytes
  pb::ServerMessage out;
  *out.mutable_view() = view_info(*v);
  return out;
}

Reply RequestHandler::query(const pb::QueryFrames& r) const {
  const View* v = find_view(r.view_id());
  if (!v) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown view " + std::to_string(r.view_id())};
  // A live view's one frame is its source's newest (the last it had, once
  // the source ended).
  std::shared_ptr<const Motion> newest = v->content()->motion;
  if (auto source = v->live_source(); source && !source->ended()) {
    auto now = source->view_motion(*v->content());
    if (!now.ok()) return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, now.error().to_string()};
    newest = std::move(now).value();
  }
  const Motion& m = *newest;
  const std::uint64_t begin = r.begin();
  const std::uint64_t end = r.end() == 0 ? begin + 1 : r.end();
  if (!(begin < end && end <= m.frame_count)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "frames [" + std::to_string(begin) + ", " + std::to_string(end) +
                                                   ") are not within the motion's " + std::to_string(m.frame_count) +
                                                   " frames"};
  }
  auto joints = resolve_joints(*v, {r.joints().begin(), r.joints().end()});
  if (!joints.ok()) return Refusal{pb::ERROR_CODE_NOT_FOUND, joints.error().message};
  const auto basis = output_basis_of(r.conventions(), motion_unit(*v));
  if (!basis.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, basis.error().message};
  // Refuse before computing anything a reply too big to send.
  const std::uint64_t per_frame =
      joints->size() * (3 + (r.orientations() ? 4 : 0) + (r.local_transforms() ? 7 : 0)) * 9 + 8;
  const std::uint64_t estimate = (end - begin) * per_frame + 64;
  if (estimate > server_.cfg.max_message_bytes) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "a query of " + std::to_string(end - begin) + " frames would take about " +
                       std::to_string(estimate) + " bytes, above the limit of " +
                       std::to_string(server_.cfg.max_message_bytes) + ": ask for fewer frames"};
  }
  pb::ServerMessage out;
  auto* b = out.mutable_frames();
  b->set_view_id(v->id());
  b->set_skeleton_version(v->content()->skeleton_version);
  b->set_begin(static_cast<std::uint32_t>(begin));
  b->set_end(static_cast<std::uint32_t>(end));
  for (int j : *joints) b->add_joints(static_cast<std::uint32_t>(j));
  const std::size_t n = m.skeleton.size();
  const int viewer = v->content()->relative_to;
  std::vector<Eigen::Vector3d> pos(n);
  std::vector<Eigen::Matrix3d> rot(r.orientations() || viewer >= 0 || r.local_transforms() ? n : 0);
  const std::vector<int> own_frames = r.local_transforms() ? own_frame_sources(m) : std::vector<int>{};
  std::vector<Eigen::Quaterniond> local_rotations(r.local_transforms() ? joints->size() : 0);
  std::vector<Eigen::Vector3d> local_translations(local_rotations.size());
  b->mutable_positions()->Reserve(static_cast<int>((end - begin) * joints->size() * 3));
  for (std::uint64_t f = begin; f < end; ++f) {
    view_frame(m, viewer, f, pos, rot, *basis);
    if (r.local_transforms()) {
      engine_locals(m.skeleton, own_frames, pos, rot, *joints, local_rotations, local_translations);
      for (std::size_t i = 0; i < joints->size(); ++i) {
        const auto& q = local_rotations[i];
        const auto& t = local_translations[i];
        const double qv[] = {q.x(), q.y(), q.z(), q.w()}, tv[] = {t.x(), t.y(), t.z()};
        b->mutable_local_rotations()->Add(std::begin(qv), std::end(qv));
        b->mutable_local_translations()->Add(std::begin(tv), std::end(tv));
      }
    }
    for (int j : *joints) {
      const auto& p = pos[static_cast<std::size_t>(j)];
      b->add_positions(p.x());
      b->add_positions(p.y());
      b->add_positions(p.z());
      if (r.orientations()) {
        const Eigen::Quaterniond q(rot[static_cast<std::size_t>(j)]);
        b->add_orientations(q.x());
        b->add_orientations(q.y());
        b->add_orientations(q.z());
        b->add_orientations(q.w());
      }
    }
  }
  return out;
}

Reply RequestHandler::stats() {
  auto c = connection_.lock();
  const ConnectionCounters own = c ? c->counters() : ConnectionCounters{};
  pb::ServerMessage out;
  auto* st = out.mutable_stats();
  st->set_connections(static_cast<std::uint32_t>(server_.connections.size()));
  st->set_streams(static_cast<std::uint32_t>(server_.streams.live()));
  st->set_frames_computed(server_.counters.frames_computed);
  st->set_frames_computed_float(server_.counters.frames_computed_float);
  st->set_frames_encoded(server_.counters.frames_encoded);
  st->set_frames_sent(own.frames_sent);
  st->set_frames_dropped(own.frames_dropped);
  // Every connection's, in one snapshot: what a load test measures its
  // window with (2 requests, not 2 per client).
  ConnectionCounters all;
  for (const auto& [transport, closed] : server_.closed_counters) all.add_totals(closed);
  for (const auto& [id, entry] : server_.connections) {
    if (auto open = entry.connection.lock()) all.add_totals(open->counters());
  }
  st->set_frames_sent_total(all.frames_sent);
  st->set_frames_dropped_total(all.frames_dropped);
  st->set_frames_skipped(own.frames_skipped);
  st->set_frames_skipped_total(server_.counters.frames_skipped);
  st->set_queued_bytes(own.queued_bytes);
  st->set_max_queued_bytes(own.max_queued_bytes);
  st->set_committed_frames_per_second(static_cast<double>(server_.committed_mhz) / 1000.0);
  st->set_send_budget(server_.cfg.send_budget);
  st->set_subscriptions_refused(server_.subscriptions_refused);
  st->set_live_sources(static_cast<std::uint32_t>(server_.live.size()));
  st->set_live_frames_received(server_.live_frames_received);
  st->set_live_frames_refused(server_.live_frames_refused);
  st->set_multicast_frames_sent(server_.multicast_frames_sent);
  st->set_io_threads(static_cast<std::uint32_t>(server_.lanes ? server_.lanes->size() : 1));
  if (auto conn = connection_.lock()) st->set_io_thread(static_cast<std::uint32_t>(conn->lane()));
  return out;
}

std::uint64_t RequestHandler::owned_bytes(const View& v) const {
  if (v.live()) return 0;  // one frame, the size of a reply
  auto it = server_.by_name.find(v.motion_name());
  const Motion* own = &v.motion();
  if (it != server_.by_name.end() && server_.library[it->second].motion.get() == own) return 0;
  // The copy (double) and, once a float32 stream uses it, its float form: the
  // values as floats and the one-frame kernel's frame-major copy of the angles.
  return own->values.size() * (sizeof(double) + 2 * sizeof(float));
}

void RequestHandler::forget_view(const View& v) {
  const std::uint64_t bytes = owned_bytes(v);
  view_bytes_ -= bytes;
  server_.view_bytes -= bytes;
}

View* RequestHandler::find_view(std::uint32_t id) const {
  auto it = views_.find(id);
  return it == views_.end() ? nullptr : it->second.get();
}

Result<std::vector<int>> RequestHandler::resolve_joints(const View& v, const std::vector<std::string>& names) const {
  std::vector<int> out;
  if (names.empty()) {
    for (int j = 0; j < static_cast<int>(v.motion().skeleton.size()); ++j) out.push_back(j);
    return out;
  }
  for (const auto& n : names) {
    auto j = v.joint_index(n);
    if (!j.ok()) return j.error();
    out.push_back(*j);
  }
  return out;
}

pb::ViewInfo RequestHandler::view_info(const View& v) const {
  pb::ViewInfo info;
  info.set_view_id(v.id());
  info.set_motion(v.motion_name());
  info.set_skeleton_version(v.content()->skeleton_version);
  wire::to_proto(v.motion(), OutputBasis{}, *info.mutable_skeleton());
  if (v.content()->relative_to >= 0) info.set_relative_to(v.motion().skeleton.joint(v.content()->relative_to).name);
  info.set_frame_count(v.motion().frame_count);
  info.set_frame_time(v.motion().frame_time);
  return info;
}

double RequestHandler::motion_unit(const View& v) const {
  if (v.live()) {
    const auto source = v.live_source();
    return source ? source->metres_per_unit() : 0.0;
  }
  const auto it = server_.by_name.find(v.motion_name());
  return it == server_.by_name.end() ? 0.0 : server_.library[it->second].metres_per_unit;
}

}  // namespace gmr::server
