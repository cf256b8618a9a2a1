#include "streams/stream_registry.h"

#include <cstdio>
#include <functional>
#include <string>

namespace gmr::server {

std::string StreamRegistry::share_key(const std::string& motion_name, const ViewContent& content,
                                      const Stream::Settings& s) {
  std::string structure;
  for (const auto& j : content.motion->skeleton.joints()) {
    structure += j.name + "<" + std::to_string(j.parent) + "," + std::to_string(j.soft_parent) + ";";
  }
  const Stream::Schedule& c = s.schedule;
  // The skeleton version goes in too: every frame carries its view's own.
  std::string key =
      motion_name + "@" + std::to_string(content.library_version) + "|" + std::to_string(content.skeleton_version) +
      "|" + std::to_string(std::hash<std::string>{}(structure)) + "|" + std::to_string(content.relative_to) + "|" +
      std::to_string(s.orientations) + std::to_string(s.local_transforms) + std::to_string(s.float64) + "|" +
      std::to_string(c.start) + ":" + std::to_string(c.end) + "|" + std::to_string(c.loop) + "|" +
      std::to_string(c.speed) + "|" + std::to_string(c.rate) + "|" + std::to_string(c.skip_repeats) + "|";
  for (int j : s.joints) key += std::to_string(j) + ",";
  // The conventions, exactly (to_string's six decimals would let two unit
  // scales that differ past them share a stream).
  char number[32];
  key += "|";
  for (int i = 0; i < 9; ++i) key += std::to_string(static_cast<int>(s.basis.b(i / 3, i % 3))) + ",";
  std::snprintf(number, sizeof number, "%.17g", s.basis.scale);
  key += number;
  return key;
}

std::shared_ptr<Stream> StreamRegistry::find_running(const std::string& key) {
  auto it = shared_.find(key);
  if (it == shared_.end()) return nullptr;
  auto s = it->second.lock();
  return s && !s->paused() && !s->idle() ? s : nullptr;
}

std::shared_ptr<Stream> StreamRegistry::find(std::uint64_t id) const {
  auto it = streams_.find(id);
  return it == streams_.end() ? nullptr : it->second.lock();
}

std::shared_ptr<Stream> StreamRegistry::create(std::shared_ptr<const ViewContent> content, Stream::Settings settings,
                                               const std::string& key) {
  prune();
  auto s = std::make_shared<Stream>(clock_, next_id_++, std::move(content), std::move(settings), counters_);
  streams_[s->id()] = s;
  if (!key.empty()) {
    s->set_share_key(key);
    shared_[key] = s;
  }
  return s;
}

std::shared_ptr<Stream> StreamRegistry::detach(const std::shared_ptr<Stream>& stream, const Target* target) {
  if (stream->target_count() <= 1) {
    if (!stream->share_key().empty()) {
      shared_.erase(stream->share_key());
      stream->set_share_key({});
    }
    return stream;
  }
  prune();
  auto own = stream->split_off(next_id_++, target);
  streams_[own->id()] = own;
  return own;
}

std::size_t StreamRegistry::live() {
  prune();
  return streams_.size();
}

std::size_t StreamRegistry::active() {
  std::size_t n = 0;
  for (auto& [id, w] : streams_) {
    if (auto s = w.lock(); s && !s->idle()) ++n;
  }
  return n;
}

std::size_t StreamRegistry::end_where(const std::function<std::string(const ViewContent&)>& why) {
  prune();
  std::size_t ended = 0;
  for (auto& [id, w] : streams_) {
    auto s = w.lock();
    if (!s || s->idle()) continue;
    if (const std::string reason = why(*s->content()); !reason.empty()) {
      s->end_targets(reason);
      s->stop();
      ++ended;
    }
  }
  return ended;
}

void StreamRegistry::stop_all() {
  prune();
  for (auto& [id, w] : streams_) {
    if (auto s = w.lock()) s->stop();
  }
  clock_.stop();
}

void StreamRegistry::prune() {
  std::erase_if(streams_, [](const auto& kv) { return kv.second.expired(); });
  std::erase_if(shared_, [](const auto& kv) { return kv.second.expired(); });
}

}  // namespace gmr::server
