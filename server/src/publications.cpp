// RequestHandler's live sources (docs/protocol.md, "Live sources"): a
// connection with a 'publish' role announces a skeleton, then pushes frames;
// its sources end when it says so or when it goes away.
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <future>

#include "gmr/io/motion_file.h"

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

// A new file in `dir` for a recording of `name`: the name with anything but
// letters, digits, '.', '-' and '_' made '_', the UTC time, .gmrb.
std::filesystem::path recording_path(const std::string& dir, const std::string& name) {
  std::string stem;
  for (const char c : name) {
    const bool plain = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                       c == '-' || c == '_';
    stem += plain ? c : '_';
  }
  if (stem.empty() || stem.front() == '.') stem = "live" + stem;
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm utc{};
  gmtime_r(&now, &utc);
  char when[32];
  std::strftime(when, sizeof when, "%Y%m%dT%H%M%SZ", &utc);
  std::filesystem::path p = std::filesystem::path(dir) / (stem + "-" + when + ".gmrb");
  for (int n = 2; std::filesystem::exists(p); ++n) {
    p = std::filesystem::path(dir) / (stem + "-" + when + "-" + std::to_string(n) + ".gmrb");
  }
  return p;
}

}  // namespace

std::shared_ptr<LiveSource> RequestHandler::find_live(std::string_view name) const {
  auto it = server_.live.find(name);
  return it == server_.live.end() || it->second->ended() ? nullptr : it->second;
}

std::variant<Skeleton, Refusal> check_announcement(const pb::Publish& r, const ServerConfig& cfg) {
  if (const std::string why = bad_name(r.name()); !why.empty()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, why};
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
    return Refusal{pb::ERROR_CODE_BAD_REQUEST,
                   fmt::format("frame time {} s: the rate must be within [{}, {}] Hz", ft, kMinRateHz, kMaxRateHz)};
  }
  if (!(std::isfinite(r.metres_per_unit()) && r.metres_per_unit() >= 0.0)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "metres per unit must be 0 (unknown) or positive"};
  }
  return std::move(skeleton).value();
}

Reply RequestHandler::publish(const pb::Publish& r) {
  if (role_ < Role::kPublish) {
    return Refusal{pb::ERROR_CODE_PERMISSION_DENIED,
                   "this connection's role is '" + std::string(role_name(role_)) +
                       "': publishing a live source needs a 'publish' token (docs/security.md)"};
  }
  const ServerConfig& cfg = server_.cfg;
  auto checked = check_announcement(r, cfg);
  if (auto* refusal = std::get_if<Refusal>(&checked)) return std::move(*refusal);
  if (server_.by_name.contains(r.name()) || find_live(r.name())) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   "a motion named '" + r.name() + "' is already served: publish under another name"};
  }
  if (publications_.size() >= cfg.max_publications_per_connection) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "at most " + std::to_string(cfg.max_publications_per_connection) +
                                                          " live sources per connection"};
  }
  std::string recording;
  if (r.record()) {
    if (cfg.record_dir.empty()) {
      return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                     "this server records no live sources (start it with --record-dir DIR)"};
    }
    recording = recording_path(cfg.record_dir, r.name()).string();
  }
  auto source = std::make_shared<LiveSource>(r.name(), server_.next_live_serial++,
                                             std::move(std::get<Skeleton>(checked)), r.frame_time(), r.metres_per_unit());
  if (!recording.empty()) {
    source->record(cfg.max_record_bytes);
    recordings_[source.get()] = recording;
  }
  const std::uint32_t id = next_publication_++;
  server_.live[r.name()] = source;
  publications_[id] = source;
  server_.relay_announce(*source);
  spdlog::info("conn {}: publishes live {} ({} joints, {} channels, {:.1f} Hz)", connection_id_,
               printable(r.name(), 200), source->latest()->skeleton.size(), source->latest()->stride(), 1.0 / r.frame_time());
  pb::ServerMessage out;
  out.mutable_published()->set_publication_id(id);
  out.mutable_published()->set_motion(r.name());
  out.mutable_published()->set_recording(recording);
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
  server_.relay_frame(source, std::span<const double>(r.values().data(), static_cast<std::size_t>(r.values_size())));
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
  server_.relay_end(*source, reason);
  if (auto path = recordings_.extract(source.get())) {
    bool truncated = false;
    auto motion = source->recording(&truncated);
    if (!motion || motion->frame_count == 0) {
      spdlog::info("live {}: nothing recorded (no frames)", printable(source->name(), 200));
      return;
    }
    // Written off the I/O thread (save_motion is atomic: a file appears
    // whole or not at all); Server::wait() waits for it.
    std::erase_if(server_.recordings, [](std::future<void>& f) {
      return f.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    });
    server_.recordings.push_back(std::async(std::launch::async, [motion, file = std::move(path.mapped()),
                                                                 name = source->name(), truncated] {
      if (Status s = save_motion(*motion, file); !s.ok()) {
        spdlog::error("live {}: recording not written: {}", printable(name, 200), s.error().to_string());
        return;
      }
      spdlog::info("live {}: recorded {} frames to {}{}", printable(name, 200), motion->frame_count, file,
                   truncated ? " (cut at --max-record-bytes)" : "");
    }));
  }
}

}  // namespace gmr::server
