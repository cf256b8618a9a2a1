// RequestHandler's live sources (docs/protocol.md, "Live sources"): a
// connection with a 'publish' role announces a skeleton, then pushes frames;
// its sources end when it says so or when it goes away.
#include <spdlog/spdlog.h>

#include <cmath>

#include "gmr/wire/convert.h"
#include "live.h"
#include "request_handler.h"

namespace gmr::server {

namespace {

constexpr std::size_t kMaxLiveNameBytes = 200;

// Why `name` cannot name a motion (empty: it can).
std::string bad_name(std::string_view name) {
  if (name.empty()) return "a live source needs a name";
  if (name.size() > kMaxLiveNameBytes) {
    return "a name of " + std::to_string(name.size()) + " bytes; at most " + std::to_string(kMaxLiveNameBytes);
  }
  for (const unsigned char c : name) {
    if (c < 0x20 || c == 0x7f) return "the name has a control character";
  }
  return {};
}

}  // namespace

std::shared_ptr<LiveSource> RequestHandler::find_live(std::string_view name) const {
  auto it = server_.live.find(name);
  return it == server_.live.end() || it->second->ended() ? nullptr : it->second;
}

Reply RequestHandler::publish(const pb::Publish& r) {
  if (role_ < Role::kPublish) {
    return Refusal{pb::ERROR_CODE_PERMISSION_DENIED,
                   "this connection's role is '" + std::string(role_name(role_)) +
                       "': publishing a live source needs a 'publish' token (docs/security.md)"};
  }
  const ServerConfig& cfg = server_.cfg;
  if (const std::string why = bad_name(r.name()); !why.empty()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, why};
  if (server_.by_name.contains(r.name()) || find_live(r.name())) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   "a motion named '" + r.name() + "' is already served: publish under another name"};
  }
  if (publications_.size() >= cfg.max_publications_per_connection) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "at most " + std::to_string(cfg.max_publications_per_connection) +
                                                          " live sources per connection"};
  }
  if (static_cast<std::size_t>(r.skeleton().joints_size()) > cfg.max_live_joints) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "a skeleton of " + std::to_string(r.skeleton().joints_size()) +
                                                          " joints; live sources have at most " +
                                                          std::to_string(cfg.max_live_joints)};
  }
  if (r.skeleton().joints_size() == 0) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "the skeleton has no joints"};
  auto skeleton = wire::from_proto(r.skeleton());
  if (!skeleton.ok()) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "the skeleton of '" + r.name() + "': " + skeleton.error().message};
  }
  const double ft = r.frame_time();
  if (!(std::isfinite(ft) && ft > 0.0 && 1.0 / ft >= kMinRateHz && 1.0 / ft <= kMaxRateHz)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "frame time " + std::to_string(ft) + " s: the rate must be within [" +
                                                   std::to_string(kMinRateHz) + ", " + std::to_string(kMaxRateHz) +
                                                   "] Hz"};
  }
  if (!(std::isfinite(r.metres_per_unit()) && r.metres_per_unit() >= 0.0)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "metres per unit must be 0 (unknown) or positive"};
  }
  auto source = std::make_shared<LiveSource>(r.name(), server_.next_live_serial++, std::move(skeleton).value(), ft,
                                             r.metres_per_unit());
  const std::uint32_t id = next_publication_++;
  server_.live[r.name()] = source;
  publications_[id] = source;
  spdlog::info("conn {}: publishes live {} ({} joints, {} channels, {:.1f} Hz)", connection_id_,
               printable(r.name(), 200), source->latest()->skeleton.size(), source->latest()->stride(), 1.0 / ft);
  pb::ServerMessage out;
  out.mutable_published()->set_publication_id(id);
  out.mutable_published()->set_motion(r.name());
  return out;
}

Reply RequestHandler::publish_frame(const pb::PublishFrame& r) {
  auto it = publications_.find(r.publication_id());
  if (it == publications_.end()) {
    ++server_.live_frames_refused;
    return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown publication " + std::to_string(r.publication_id())};
  }
  LiveSource& source = *it->second;
  if (Status s = source.push(std::span<const double>(r.values().data(), static_cast<std::size_t>(r.values_size())));
      !s.ok()) {
    ++server_.live_frames_refused;
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "live '" + source.name() + "': " + s.error().message};
  }
  ++server_.live_frames_received;
  return pb::ServerMessage{};  // no reply
}

Reply RequestHandler::unpublish(const pb::Unpublish& r) {
  if (!publications_.contains(r.publication_id())) {
    return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown publication " + std::to_string(r.publication_id())};
  }
  end_publication(r.publication_id(), "the live source ended");
  pb::ServerMessage out;
  out.mutable_ack();
  return out;
}

void RequestHandler::end_publication(std::uint32_t id, const std::string& reason) {
  auto it = publications_.find(id);
  if (it == publications_.end()) return;
  auto source = std::move(it->second);
  publications_.erase(it);
  if (auto l = server_.live.find(source->name()); l != server_.live.end() && l->second == source) {
    server_.live.erase(l);
  }
  spdlog::info("conn {}: live {} ended after {} frames: {}", connection_id_, printable(source->name(), 200),
               source->frames(), reason);
  source->end(reason);
}

}  // namespace gmr::server
