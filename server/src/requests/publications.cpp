// RequestHandler's live sources (docs/protocol.md, "Live sources"): a
// connection with a 'publish' role announces a skeleton, then pushes frames;
// its sources end when it says so or when it goes away.
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>

#include "live/announcement.h"
#include "live/live_source.h"
#include "requests/request_handler.h"

namespace gmr::server {

namespace {

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

Reply RequestHandler::publish(const pb::Publish& r) {
  if (role_ < Role::kPublish) {
    return Refusal{pb::ERROR_CODE_PERMISSION_DENIED,
                   "this connection's role is '" + std::string(role_name(role_)) +
                       "': publishing a live source needs a 'publish' token (docs/security.md)"};
  }
  const ServerConfig& cfg = services_.cfg;
  auto checked = check_announcement(r, cfg);
  if (auto* refusal = std::get_if<Refusal>(&checked)) return std::move(*refusal);
  if (services_.catalog.find(r.name())) {
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
  auto source = services_.catalog.add_live(r.name(), std::move(std::get<Skeleton>(checked)), r.frame_time(),
                                          r.metres_per_unit());
  if (!recording.empty()) {
    source->record(cfg.max_record_bytes);
    recordings_[source.get()] = recording;
  }
  const std::uint32_t id = next_publication_++;
  publications_[id] = source;
  services_.replicas.announce(*source);
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
    services_.catalog.count_live_frame(false);
    return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown publication " + std::to_string(r.publication_id())};
  }
  LiveSource& source = *it->second;
  if (Status s = source.push(std::span<const double>(r.values().data(), static_cast<std::size_t>(r.values_size())));
      !s.ok()) {
    services_.catalog.count_live_frame(false);
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "live '" + source.name() + "': " + s.error().message};
  }
  services_.catalog.count_live_frame(true);
  services_.replicas.frame(source, std::span<const double>(r.values().data(), static_cast<std::size_t>(r.values_size())));
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
  services_.catalog.remove_live(source);
  spdlog::info("conn {}: live {} ended after {} frames: {}", connection_id_, printable(source->name(), 200),
               source->frames(), reason);
  source->end(reason);
  services_.replicas.end(*source, reason);
  if (auto path = recordings_.extract(source.get())) {
    bool truncated = false;
    auto motion = source->recording(&truncated);
    if (!motion || motion->frame_count == 0) {
      spdlog::info("live {}: nothing recorded (no frames)", printable(source->name(), 200));
      return;
    }
    // Written off the I/O thread (save_motion is atomic: a file appears
    // whole or not at all); the server waits for it when it stops.
    services_.recordings.write(std::move(motion), std::move(path.mapped()), source->name(), truncated);
  }
}

}  // namespace gmr::server
